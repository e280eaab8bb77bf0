// How far apart the end caps around a pole of valence N and their regular neighbours evaluate their
// shared edges (issue 15; docs/subdivision-compare.md, "Above valence 256"): the disk of
// scripts/pole_shape.py at isolation level 4, each end cap's edges u = 1/16 and v = 1/16 evaluated by
// both patches (PatchMap, PatchTable::EvaluateBasis) at 513 points: the largest distance at equal
// parameters, and the largest distance from a point of one curve to the other (every 8th point to
// all 513 of the other side: a set distance, resolved to ~2e-5 of the diagonal). Build and run:
//   g++ -O2 -std=c++17 scripts/endcap_gap.cpp -losdCPU -o /tmp/endcap_gap
//   /tmp/endcap_gap 300 bilinear
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/far/topologyRefinerFactory.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>
namespace Far = OpenSubdiv::Far; namespace Sdc = OpenSubdiv::Sdc;
struct V { double x[3]; void Clear(void* = 0) { x[0] = x[1] = x[2] = 0; }
  void AddWithWeight(const V& s, float w) { for (int i = 0; i < 3; ++i) x[i] += w * s.x[i]; } };
int main(int argc, char** argv) {
  int n = atoi(argv[1]); const char* cap = argv[2]; int iso = 4;
  std::vector<int> counts(n, 4), idx; std::vector<V> pts(1 + 2 * n);
  pts[0] = {{0, 0, 0.3}};
  for (int i = 0; i < n; ++i) { double a = 2 * M_PI * i / n, b = 2 * M_PI * (i + 0.5) / n;
    pts[1 + 2 * i] = {{cos(a), sin(a), 0.1}}; pts[2 + 2 * i] = {{1.4 * cos(b), 1.4 * sin(b), 0}};
    int j = (i + 1) % n; int f[4] = {0, 1 + 2 * i, 2 + 2 * i, 1 + 2 * j}; idx.insert(idx.end(), f, f + 4); }
  Far::TopologyDescriptor td; td.numVertices = 1 + 2 * n; td.numFaces = n;
  td.numVertsPerFace = counts.data(); td.vertIndicesPerFace = idx.data();
  Sdc::Options so; so.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
  Far::TopologyRefiner* r = Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Create(td,
      Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Options(Sdc::SCHEME_CATMARK, so));
  Far::PatchTableFactory::Options po(iso);
  po.SetEndCapType(!strcmp(cap, "gregory") ? Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS :
                   !strcmp(cap, "bspline") ? Far::PatchTableFactory::Options::ENDCAP_BSPLINE_BASIS :
                   Far::PatchTableFactory::Options::ENDCAP_BILINEAR_BASIS);
  po.useInfSharpPatch = true; po.generateVaryingTables = false;
  r->RefineAdaptive(po.GetRefineAdaptiveOptions());
  Far::PatchTable* pt = Far::PatchTableFactory::Create(*r, po);
  std::vector<V> cv(r->GetNumVerticesTotal() + pt->GetNumLocalPoints());
  std::copy(pts.begin(), pts.end(), cv.begin());
  Far::PrimvarRefiner pr(*r); V* src = cv.data();
  for (int l = 1; l <= r->GetMaxLevel(); ++l) { V* dst = src + r->GetLevel(l - 1).GetNumVertices(); pr.Interpolate(l, src, dst); src = dst; }
  pt->ComputeLocalPointValues(cv.data(), cv.data() + r->GetNumVerticesTotal());
  Far::PatchMap map(*pt);
  auto eval = [&](const Far::PatchTable::PatchHandle& h, double u, double v, double out[3]) {
    float w[20], wu[20], wv[20]; pt->EvaluateBasis(h, float(u), float(v), w, wu, wv);
    Far::ConstIndexArray c = pt->GetPatchVertices(h); out[0] = out[1] = out[2] = 0;
    for (int k = 0; k < c.size(); ++k) for (int a = 0; a < 3; ++a) out[a] += double(w[k]) * cv[c[k]].x[a]; };
  // The end cap at the pole corner (u, v = 0) of ptex face f spans [0, e]²; its edges u = e and v = e
  // meet regular patches.
  double e = 1.0 / (1 << iso), worst = 0, diag = 2.8, hd = 0;
  auto dist = [](const double* p, const double* q) { return std::sqrt((p[0]-q[0])*(p[0]-q[0]) + (p[1]-q[1])*(p[1]-q[1]) + (p[2]-q[2])*(p[2]-q[2])); };
  for (int f = 0; f < n; ++f)
    for (int side = 0; side < 2; ++side) {
      const int M = 512;
      std::vector<double> ca(3 * (M + 1)), nb(3 * (M + 1));
      const Far::PatchTable::PatchHandle* a = map.FindPatch(f, side ? e - 1e-9 : e / 2, side ? e / 2 : e - 1e-9);
      const Far::PatchTable::PatchHandle* b = map.FindPatch(f, side ? e + 1e-9 : e / 2, side ? e / 2 : e + 1e-9);
      for (int k = 0; k <= M; ++k) {
        double t = e * k / M, u = side ? e : t, v = side ? t : e;
        eval(*a, u, v, &ca[3 * k]); eval(*b, u, v, &nb[3 * k]);
        worst = std::max(worst, dist(&ca[3 * k], &nb[3 * k]));
      }
      // Set distance: each point of one side to the nearest sample of the other (both ways).
      for (int pass = 0; pass < 2; ++pass) {
        const std::vector<double>& x = pass ? nb : ca; const std::vector<double>& y = pass ? ca : nb;
        for (int k = 0; k <= M; k += 8) {
          double best = 1e30;
          for (int j = 0; j <= M; ++j) best = std::min(best, dist(&x[3 * k], &y[3 * j]));
          hd = std::max(hd, best);
        }
      }
    }
  printf("valence %d %s end caps: same-parameter gap to the regular neighbours %.2e of the diagonal, set (Hausdorff) distance %.2e\n", n, cap, worst / diag, hd / diag);
  return 0;
  printf("valence %d %s end caps: largest gap to the regular neighbours %.2e (%.2e of the diagonal)\n", n, cap, worst, worst / diag);
}
