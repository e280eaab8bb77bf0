// The cost of OpenSubdiv's end caps around a pole of valence N (issue 15; docs/subdivision-compare.md,
// "Above valence 256"): the disk of scripts/pole_shape.py, adaptively refined to level 4, its patch
// table built with END_CAP = gregory | bspline | bilinear end caps; prints the time, patches, local
// points, local-point stencil weights and peak RSS. Build and run (outside the crate builds):
//   g++ -O2 -std=c++17 scripts/endcap_cost.cpp -losdCPU -o /tmp/endcap_cost
//   /usr/bin/time -v /tmp/endcap_cost 1440 gregory
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/far/topologyRefinerFactory.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/stencilTable.h>
#include <sys/resource.h>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>
namespace Far = OpenSubdiv::Far; namespace Sdc = OpenSubdiv::Sdc;
int main(int argc, char** argv) {
  int n = atoi(argv[1]); const char* cap = argv[2]; int iso = argc > 3 ? atoi(argv[3]) : 4;
  std::vector<int> counts(n, 4), idx;
  for (int i = 0; i < n; ++i) { int j = (i + 1) % n; int f[4] = {0, 1 + 2 * i, 2 + 2 * i, 1 + 2 * j}; idx.insert(idx.end(), f, f + 4); }
  Far::TopologyDescriptor td; td.numVertices = 1 + 2 * n; td.numFaces = n;
  td.numVertsPerFace = counts.data(); td.vertIndicesPerFace = idx.data();
  Sdc::Options so; so.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
  auto t0 = std::chrono::steady_clock::now();
  Far::TopologyRefiner* r = Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Create(td,
      Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Options(Sdc::SCHEME_CATMARK, so));
  Far::PatchTableFactory::Options po(iso);
  po.SetEndCapType(!strcmp(cap, "gregory") ? Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS :
                   !strcmp(cap, "bspline") ? Far::PatchTableFactory::Options::ENDCAP_BSPLINE_BASIS :
                   Far::PatchTableFactory::Options::ENDCAP_BILINEAR_BASIS);
  po.useInfSharpPatch = true; po.generateVaryingTables = false;
  r->RefineAdaptive(po.GetRefineAdaptiveOptions());
  auto t1 = std::chrono::steady_clock::now();
  Far::PatchTable* pt = Far::PatchTableFactory::Create(*r, po);
  auto t2 = std::chrono::steady_clock::now();
  const Far::StencilTable* st = pt->GetLocalPointStencilTable();
  struct rusage ru; getrusage(RUSAGE_SELF, &ru);
  printf("valence %d %s: refine %.3f s, patch table %.3f s, patches %d, local points %d, stencil weights %zu, peak RSS %.1f MB\n",
         n, cap, std::chrono::duration<double>(t1 - t0).count(), std::chrono::duration<double>(t2 - t1).count(),
         pt->GetNumPatchesTotal(), pt->GetNumLocalPoints(), st ? st->GetWeights().size() : 0, ru.ru_maxrss / 1024.0);
}
