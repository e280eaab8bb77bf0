"""Typed stubs of ``mipray._mipray``, the compiled render delegate (pyo3).

Hand-written: this file is the contract between the Rust bindings
(``python/src``) and the Python scene delegate (``mipray.usd``). Keep it in step
with the bindings; ``tests/test_protocol.py`` compares the two signatures, and
``python -m mypy.stubtest mipray._mipray`` checks them when mypy is installed.

Conventions
-----------
* Matrices are ``float64`` arrays of shape (4, 4) in USD's row-vector layout,
  exactly as ``numpy.array(Gf.Matrix4d)`` gives them: ``p_world = p @ m`` with
  the translation in the last row.
* Prim paths are USD path strings (``"/World/Geo/Cube"``); a ``set_*`` call with
  a path already present replaces that prim.
* Methods that take array data raise ``mipray.errors.PrimDataError`` (a
  ``PrimError`` and a ``ValueError``) naming the prim path when the data is
  inconsistent (index out of range, counts that do not add up, non-finite
  values). ``set_mesh`` checks a mesh's data once, here: the scene delegate
  does not check it first.
"""

from collections.abc import Callable, Mapping
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

@final
class RenderDelegate:
    """The Hydra-style render delegate: holds synced prims and renders them.

    One delegate holds one scene. Prims are added or replaced with the
    ``set_*`` methods and removed with :meth:`remove`; :meth:`render` traces
    the scene as it is at that moment.
    """

    def __init__(self) -> None:
        """Create an empty scene."""

    def set_mesh(
        self,
        path: str,
        *,
        points: NDArray[np.float32],
        face_vertex_counts: NDArray[np.int32],
        face_vertex_indices: NDArray[np.int32],
        transform: NDArray[np.float64],
        scheme: str = "catmullClark",
        interpolate_boundary: str = "edgeAndCorner",
        face_varying_linear_interpolation: str = "cornersPlus1",
        triangle_subdivision_rule: str = "catmullClark",
        crease_indices: NDArray[np.int32] | None = None,
        crease_lengths: NDArray[np.int32] | None = None,
        crease_sharpnesses: NDArray[np.float32] | None = None,
        corner_indices: NDArray[np.int32] | None = None,
        corner_sharpnesses: NDArray[np.float32] | None = None,
        hole_indices: NDArray[np.int32] | None = None,
        left_handed: bool = False,
        double_sided: bool = False,
        prototype: bool = False,
        displacement_bound: float | None = None,
        displacement: tuple[float, float, int, float] | None = None,
        st_values: NDArray[np.float32] | None = None,
        st_indices: NDArray[np.int32] | None = None,
        st_interpolation: str = "faceVarying",
        displacement_texture: dict[str, object] | None = None,
        material: dict[str, object] | None = None,
        gprim: dict[str, object] | None = None,
        primvars: dict[str, dict[str, object]] | None = None,
        face_materials: list[dict[str, object]] | None = None,
        face_material_indices: NDArray[np.int32] | None = None,
        light: dict[str, object] | None = None,
    ) -> None:
        """Add or replace a mesh (an Rprim).

        Args:
            path: the prim path; names the mesh in errors and stats.
            points: (N, 3) float32 object-space control points.
            face_vertex_counts: (F,) int32 vertices per face.
            face_vertex_indices: (sum of counts,) int32 indices into ``points``.
            transform: (4, 4) float64 local-to-world, row-vector convention.
            scheme: USD ``subdivisionScheme``; ``"none"`` is a polygonal mesh.
            interpolate_boundary: USD ``interpolateBoundary``.
            face_varying_linear_interpolation: USD
                ``faceVaryingLinearInterpolation``.
            triangle_subdivision_rule: USD ``triangleSubdivisionRule``.
            crease_indices: int32 vertex indices of all creases, concatenated.
            crease_lengths: int32 number of vertices of each crease.
            crease_sharpnesses: float32, one per crease or one per crease edge.
            corner_indices: int32 vertex indices of sharp corners.
            corner_sharpnesses: float32, one per corner.
            hole_indices: int32 indices of faces that are holes.
            left_handed: True when USD ``orientation`` is ``leftHanded``.
            double_sided: USD ``doubleSided``.
            prototype: a prototype of instancers (:meth:`set_instancer`): it
                renders only where an instancer places it, and ``transform``
                is then relative to its prototype's root.
            displacement_bound: ``primvars:displacementBound``, object units;
                None: the displacement's own bound, else the render setting.
            displacement: built-in fBm displacement ``(amplitude, frequency,
                octaves, gain)`` from ``mipray:displacement:*``.
            st_values: (K, 2) float32 values of the ``st`` primvar textures read.
            st_indices: int32 USD indices of an indexed ``st``, or None.
            st_interpolation: the primvar's USD interpolation.
            displacement_texture: a UsdUVTexture feeding ``displacement`` (a
                dict as in ``material``'s ``"textures"``), along the limit
                normal at tessellation time, filtered at the grid's spacing
                (coarse tiers read coarse MIP levels).
            material: the mesh's UsdPreviewSurface, the one material model:
                ``{"name": material path (default ``path``), "diffuseColor",
                "emissiveColor", "specularColor": 3 floats,
                "useSpecularWorkflow": bool, "metallic", "roughness",
                "clearcoat", "clearcoatRoughness", "opacity",
                "opacityThreshold", "ior": float, "textures": {input name:
                UsdUVTexture}}``; every key optional (an input left out keeps
                UsdPreviewSurface's fallback). A display colour without a
                material is ``{"diffuseColor": rgb, "useSpecularWorkflow":
                True, "specularColor": (0, 0, 0)}`` (lambertian); a smooth
                mirror over it adds ``"specularColor": reflectance,
                "roughness": 0``. None: lambertian 0.18 grey. A UsdUVTexture
                is ``{"file", "scale", "bias", "fallback" (4 floats each),
                "wrapS", "wrapT", "sourceColorSpace" (``auto``, the default:
                8-bit files of 3 or 4 channels are sRGB, as in Hydra; ``raw``;
                ``sRGB``), "channel" (0-3), "udim_tiles"}``; sRGB files are
                decoded into a linear MIP map once (``$MIPRAY_TEXTURE_CACHE``,
                else ``~/.cache/mipray/textures``) and filtered by the ray
                differentials. Float inputs read the texture's ``channel``;
                ``"normal"`` is a tangent-space normal map. Out-of-range values
                are clamped with one warning naming the material; an unreadable
                texture renders its ``fallback`` with one warning naming prim
                and file. ``"networks": {input name: {"ops": [(name, *floats)],
                "lookups": [UsdUVTexture + "channels" (1-4), "st_transform"
                (6 floats)], "primvars": [{"name", "components" (1-4),
                "fallback" (4 floats)}]}}``: MaterialX nodes evaluated per shading point
                (``mipray::material::network``; docs/materials.md); an input
                is in ``textures`` or ``networks``, not both.
            gprim: a gprim other than a mesh, intersected exactly (the mesh
                arguments' topology is then empty): ``{"type": "Sphere",
                "radius"}``, ``{"type": "Cube", "size"}``, ``{"type":
                "Cylinder" (also cones: ``radius_top`` 0) or "Capsule",
                "radius_bottom", "radius_top", "height", "axis"}``, ``{"type":
                "Plane", "width", "length", "axis"}`` (object units, ``axis``
                "X", "Y" or "Z"), or ``{"type": "Points", "widths"}``: spheres
                at ``points`` of diameters ``widths`` (one, one per point, or
                none for USD's default 1). ``st`` is the surface's (u, v)
                (see ``mipray::implicit``). Or curves, ray traced as curves
                with ``points`` their vertices: ``{"type": "Curves",
                "curve_vertex_counts", "curve_type" ("linear", "cubic"),
                "basis" ("bezier", "bspline", "catmullRom"), "wrap"
                ("nonperiodic", "periodic", "pinned"), "style" ("tube",
                "ribbon"), "widths", "widths_interpolation", "normals" (N×3),
                "normals_interpolation"}`` (USD's tokens; see
                ``mipray::curves``); each curve is a face of the face table.
                Or a NURBS surface (UsdGeom.NurbsPatch), tessellated on demand
                like a subdivision surface, ``points`` its control points (u
                fastest): ``{"type": "Nurbs", "u_vertex_count",
                "v_vertex_count", "u_order", "v_order", "u_knots", "v_knots",
                "u_range", "v_range" (two floats or None), "weights" (one per
                point, or empty)}``; ``st`` is the knots' (u, v) normalized
                over the range (see ``mipray::nurbs``).
            primvars: primvars interpolated over the surface as authored, by
                role: ``"normals"`` (authored normals, (N, 3), used for
                shading; meant for polygonal meshes) or a UsdPreviewSurface
                input name they feed (``"diffuseColor"`` (N, 3), a float input
                (N, 1)), or ``"geomprop:<name>"`` ((N, 1-4), read by the
                ``"primvars"`` of ``material``'s networks that name it), each
                ``{"values": float32 array, "indices": int32 or None,
                "interpolation": USD token}``; an input's primvar shades the
                faces of the mesh's own ``material``. Face-varying and vertex
                primvars go through OpenSubdiv on subdivision surfaces; every
                interpolation is linear over each face on polygonal ones.
            face_materials: materials of their own on some faces, each a dict
                as ``material``: GeomSubsets' whole UsdPreviewSurface networks
                (textures included; they read the mesh's ``st``), per-face
                display colours (lambertian).
            face_material_indices: (F,) int32, one per face in USD face order
                (holes included; one per point for Points): an index into
                ``face_materials``, or -1 for the mesh's ``material``. Given
                together with ``face_materials``.
            light: UsdLux ``MeshLightAPI``: the mesh is then an area light and
                not a surface: ``{"intensity", "exposure", "color",
                "normalize", "shadow_enable", "unlit", "no_shadow"}`` as
                :meth:`set_light` takes them, and ``"tint"`` (bool: the
                material's ``emissiveColor`` multiplies ``color``,
                UsdLux ``materialGlowTintsLight``), every key optional. Its
                limit surface, tessellated for lighting (polygons at their
                corners, subdivision patches 4×4), emits from its front faces
                (both with ``double_sided``), from every instance of a
                prototype mesh, posed at each ray's time when it moves.

        Raises:
            PrimDataError: the data is inconsistent (the one check of a mesh's
                data: points, topology, subdivision tags, primvars, face table,
                transform, displacement, widths); the message names ``path``,
                and the mesh is not kept. A ``ValueError`` too.
        """

    def set_transform(self, path: str, transform: NDArray[np.float64]) -> None:
        """Move the mesh at ``path`` without resending its data.

        The mesh is not rebuilt and keeps its geometry cache entries: the
        cheap path for a transform-only edit.

        Args:
            path: a mesh set with :meth:`set_mesh`.
            transform: (4, 4) float64 local-to-world (for a prototype mesh:
                to its prototype's root), row-vector convention.

        Raises:
            PrimDataError: no mesh at ``path``, or the transform is not finite.
        """

    def set_motion(
        self, path: str, times: NDArray[np.float32], transforms: NDArray[np.float64]
    ) -> None:
        """Set the world transform of the mesh at ``path`` over the camera's shutter.

        Transform motion blur: each camera sample gets a time in the shutter and
        sees the mesh at the transform interpolated there (scale and translation
        linearly, rotation by slerp). Fewer than two keys, or keys that do not
        differ, clear the motion.

        Args:
            path: a mesh set with :meth:`set_mesh` (not a prototype).
            times: (N,) float32 shutter fractions, 0 at open and 1 at close.
            transforms: (N, 4, 4) float64 local-to-world, row-vector convention.

        Raises:
            PrimDataError: no mesh at ``path``, lengths differ, or a key is not finite.
        """

    def set_deformation(
        self,
        path: str,
        times: NDArray[np.float32],
        points: NDArray[np.float32],
        widths: NDArray[np.float32] | None = None,
        gprims: list[dict[str, Any]] | None = None,
    ) -> None:
        """Set the points of the mesh at ``path`` at times across the camera's shutter.

        Deformation motion blur: the mesh is built at each sample over its topology,
        and a camera sample at shutter time t sees the surface of the points blended
        linearly between the two samples around t. A Points prim's spheres, a curves
        prim's control points (and widths) and an implicit prim's sizes blend the same
        way. No times clear the samples.

        Args:
            path: a polygonal or subdivision mesh, a Points, curves or implicit prim set
                with :meth:`set_mesh`.
            times: (N,) float32 shutter fractions, 0 at open and 1 at close, strictly
                increasing; N from 2 to 16, or 0.
            points: (N, P, 3) float32 object-space points, P the mesh's point count.
            widths: (N, W) float32 widths at each sample, for a Points or curves prim whose
                widths change within the shutter (W as many as the prim's own, or for
                Points 1 or one per point); None keeps the prim's widths.
            gprims: for an implicit prim whose sizes change within the shutter, its ``gprim``
                argument (as :meth:`set_mesh` takes it) at each sample, of one type and
                axis; its points are then (N, 0, 3). A ray at shutter time t meets the
                shape of sizes blended between the two samples around t, exactly.

        Raises:
            PrimDataError: no mesh at ``path``, a NurbsPatch, shapes that do not match,
                times not increasing, points or widths not finite, or gprims not one per
                sample, of another type or axis, or with sizes the shape cannot take.
        """

    def set_instancer(
        self,
        path: str,
        *,
        prototypes: list[str],
        proto_indices: NDArray[np.int32],
        transforms: NDArray[np.float64],
        prototype: bool = False,
    ) -> None:
        """Add or replace an instancer: ``prototypes[proto_indices[i]]`` placed at
        ``transforms[i]`` for every instance ``i``.

        A prototype is a mesh (usually set with ``prototype=True``) or another
        instancer; it is stored once however many instances place it, and its
        instances share its tessellations in the geometry cache. A placed mesh's
        object-to-world transform is its own ``transform`` followed by the
        instance's (and by the parents' for nested instancers). Prototypes
        may be set before or after the instancer; one that is missing when a
        render syncs is reported and its instances are left out.

        Args:
            path: the instancer's path (a PointInstancer's prim path, or a
                native prototype's).
            prototypes: paths of meshes or instancers.
            proto_indices: (N,) int32 index into ``prototypes`` per instance.
            transforms: (N, 4, 4) float64 prototype-root-to-world per instance
                (for a prototype instancer: to its parent prototype's root),
                row-vector convention.
            prototype: a prototype of other instancers: it places nothing by
                itself.

        Raises:
            PrimDataError: sizes that disagree, an index out of range, or a
                transform that is not finite; the message names ``path``.
        """

    def set_instancer_motion(
        self, path: str, times: NDArray[np.float32], transforms: NDArray[np.float64]
    ) -> None:
        """Set the transforms of the instancer at ``path``'s instances over the camera's shutter.

        Transform motion blur of instances: each mesh an instance places (nested
        instancers' included), and each mesh light, moves with the instance's
        transform interpolated at the ray's time, as :meth:`set_motion` moves a mesh.
        An instance whose keys are all equal stays at its ``set_instancer``
        transform. :meth:`set_instancer` clears the motion; no times clear it too.

        Args:
            path: an instancer set with :meth:`set_instancer`.
            times: (K,) float32 shutter fractions, 0 at open and 1 at close.
            transforms: (K, N, 4, 4) float64 per time and instance, in the frame of
                ``set_instancer``'s ``transforms``, row-vector convention; N its
                instance count.

        Raises:
            PrimDataError: no instancer at ``path``, shapes that do not match its
                instance count, or values that are not finite.
        """

    def set_camera(
        self,
        path: str,
        *,
        transform: NDArray[np.float64],
        projection: str = "perspective",
        focal_length: float = 50.0,
        horizontal_aperture: float = 20.955,
        vertical_aperture: float = 15.2908,
        horizontal_aperture_offset: float = 0.0,
        vertical_aperture_offset: float = 0.0,
        clipping_range: tuple[float, float] = ...,  # (1.0, 1e6)
        f_stop: float = 0.0,
        focus_distance: float = 0.0,
    ) -> None:
        """Add or replace a camera (an Sprim), with USD ``UsdGeomCamera`` units.

        The camera looks down its local -Z axis with +Y up. Focal length and
        apertures are in tenths of a scene unit (USD's convention, millimetres
        when the scene is in centimetres); ``f_stop`` 0 disables depth of field.

        Raises:
            ValueError: a value is out of range; the message names ``path``.
        """

    def set_light(
        self,
        path: str,
        *,
        kind: str,
        transform: NDArray[np.float64],
        intensity: float = 1.0,
        exposure: float = 0.0,
        color: tuple[float, float, float] = ...,  # (1.0, 1.0, 1.0)
        normalize: bool = False,
        shadow_enable: bool = True,
        angle: float = 0.53,
        radius: float = 0.5,
        width: float = 1.0,
        height: float = 1.0,
        texture: str | None = None,
        length: float = 1.0,
        cone_angle: float = 180.0,
        cone_softness: float = 0.0,
        focus: float = 0.0,
        focus_tint: tuple[float, float, float] = ...,  # (0.0, 0.0, 0.0)
        unlit: list[str] = ...,  # []
        no_shadow: list[str] = ...,  # []
        ies_file: str | None = None,
        ies_angle_scale: float = 0.0,
        ies_normalize: bool = False,
        ies_down: tuple[float, float, float] = ...,  # (0, -1, 0)
        ies_profile_sampling: bool = False,
        portals: list[str] | None = None,
    ) -> None:
        """Add or replace a UsdLux light of any kind (an Sprim).

        ``kind`` is ``distant`` (as :meth:`set_distant_light`), ``sphere``
        (``radius``), ``rect`` (``width`` × ``height``, emitting along local
        -Z), ``disk`` (``radius``, along -Z), ``cylinder`` (``radius``,
        ``length``, along local X, no end caps), ``dome`` (radiance from every
        direction: constant, or the latlong ``texture`` file, +Y up; ``portals``:
        the PortalLight paths its ``portals`` relationship names, ``None`` for
        every portal of the scene) or ``portal`` (a UsdLux.PortalLight,
        ``width`` × ``height`` passing light along -Z: it emits nothing and
        guides the domes' light sampling, ``mipray::light::Portal``). Area
        lights emit radiance ``color * intensity
        * 2**exposure``, divided by their area with ``normalize``; they cast
        soft shadows with ``shadowSamples`` rays each. ``cone_angle``
        (degrees), ``cone_softness``, ``focus`` and ``focus_tint`` are
        UsdLux's ShapingAPI on sphere, rect and disk lights (the defaults
        shape nothing); ``ies_file``, ``ies_angle_scale`` and ``ies_normalize``
        are its IES profile (LM-63, photometric types A, B and C, tilt tables
        read at the angle between the light's aim and ``ies_down``, the
        stage's down, as the table's lamp-to-luminaire geometry defines the
        tilt: a file that cannot be read or parsed is named in one warning
        and the light renders without it; ``ies_profile_sampling`` draws
        directions by the profile, off by default); ``unlit`` and
        ``no_shadow`` name the mesh prims the light's light- and
        shadow-linking collections leave out.

        Raises:
            ValueError: a non-finite value or a non-positive size; the message
                names ``path``.
        """

    def set_distant_light(
        self,
        path: str,
        *,
        transform: NDArray[np.float64],
        intensity: float = 1.0,
        exposure: float = 0.0,
        color: tuple[float, float, float] = ...,  # (1.0, 1.0, 1.0)
        angle: float = 0.53,
        normalize: bool = False,
        shadow_enable: bool = True,
        unlit: list[str] = ...,  # []
        no_shadow: list[str] = ...,  # []
    ) -> None:
        """Add or replace a ``UsdLuxDistantLight`` (an Sprim).

        The light shines along its local -Z axis; ``angle`` is the angular
        diameter in degrees; the emitted radiance is
        ``color * intensity * 2**exposure`` as UsdLux defines it.

        Raises:
            ValueError: a value is out of range; the message names ``path``.
        """

    def remove(self, path: str) -> None:
        """Remove the prim at ``path``; nothing happens if there is none."""

    def prim_paths(self) -> list[str]:
        """The paths of every prim the delegate holds, sorted."""

    def mesh_sync_count(self, path: str) -> int | None:
        """How many times the mesh's surface has been (re)built or updated; None if unknown."""

    def instancer_update_count(self, path: str) -> int | None:
        """How many times the instancer has been set; None if there is none."""

    def render(
        self,
        camera: str,
        width: int,
        height: int,
        aovs: list[str],
        settings: dict[str, object] | None = None,
        progress: Callable[[int, int], object] | None = None,
        *,
        on_update: Callable[[int, bool, dict[str, NDArray[np.float32]]], object] | None = None,
        pass_output: dict[str, Any] | None = None,
    ) -> tuple[Mapping[str, NDArray[np.float32]], str]:
        """Render the scene through ``camera`` and return its AOVs.

        Releases the GIL for the whole render; the render thread re-takes it
        only to call ``progress`` and ``on_update``.

        Args:
            camera: path of a camera set with :meth:`set_camera`.
            width: image width in pixels.
            height: image height in pixels.
            aovs: names of the AOVs to produce: ``"color"`` (3 channels,
                linear), ``"depth"`` (1 channel, camera-space distance along
                the view axis in scene units, the far clipping distance where
                nothing is hit), ``"normal"`` (3 channels, world space), and
                the others of ``aov_names()`` — README's AOV table says what
                each holds (``"cameraDepth"``, ``"Peye"``: Hydra's
                camera-space depth and position).
            settings: renderer settings, all optional: ``"samples"`` (int,
                per pixel, default 1), ``"seed"`` (int), ``"threads"`` (int,
                0 for all cores), ``"tessFactor"`` (float, the paper's tess
                factor: larger is coarser), ``"geometryCacheMb"`` (float),
                ``"cacheMode"`` (``"multires"``, ``"single"``,
                ``"unbounded"`` or ``"none"``), ``"displacementBound"``
                (float, scene units), ``"progressive"`` (0 or 1: render in
                passes of 1, 2, 4, ... samples per pixel up to ``"samples"``;
                the final image is bit-identical to a one-pass render with
                the same seed). The module may know more; it rejects unknown
                keys with ``ValueError``.
            progress: called as ``progress(done, total)`` about every 1% of
                the work (units: pixel samples, over all passes).
            on_update: called as ``on_update(samples, converged, aovs)`` after
                each pass, in order, from a render thread: ``samples`` is the
                samples per pixel so far, ``converged`` is True for the last
                pass only, and ``aovs`` maps each AOV asked for to a
                read-only H×W×C float32 array (linear, averaged over the
                samples so far) viewing that pass's own buffers in place
                (its ``base`` owns them): the caller may keep it, later
                passes do not touch it. Without ``"progressive"`` there
                is one pass, so one call. An exception raised in it cancels
                the render (no further pass starts) and is raised by
                ``render`` as it was raised; the delegate stays usable.
            pass_output: ``{"path": str, "aovs": [names], "color_correction":
                str, "metadata": dict}`` (as :func:`write_image`): every pass
                but the last is written there atomically by the render
                thread, with ``mipray:progressiveSamples``, before
                ``on_update`` is called for it. A failed write cancels the
                render and raises ``OSError``.

        Ctrl-C cancels the render: while it runs, the calling thread runs
        Python's signal handlers every 20 ms, and what they raise
        (``KeyboardInterrupt``) stops the sync, the pre-pass and the tiles
        and is raised here once the render threads have stopped.

        Returns:
            ``(aovs, stats_json)``: the AOVs, and the render statistics as
            a JSON string (names in DESIGN.md). ``aovs`` is a read-only
            mapping, AOV name → H×W×C float32 array, that keeps the buffers
            the renderer filled: each ``aovs[name]`` is a new array object
            viewing the buffer in place (its ``base`` is ``aovs``, kept
            alive by it), so no pixel is copied, and :func:`write_image`
            reads such arrays where they are. The arrays are read-only
            (numpy refuses to make them writeable; ``numpy.array(a)`` is a
            copy to change). ``keys`` (a list), ``values``, ``items``,
            ``get``, ``len``, ``in`` and iteration work as on a dict.

        Raises:
            ValueError: unknown camera or AOV, or an invalid setting.
            KeyboardInterrupt: the render was interrupted (Ctrl-C).
            BaseException: whatever ``on_update`` raised.
        """

def write_image(
    path: str,
    aovs: dict[str, NDArray[np.float32]],
    order: list[str] | None = None,
    formats: dict[str, str] | None = None,
    metadata: dict[str, object] | None = None,
    *,
    color_correction: str = "disabled",
    atomic: bool = False,
) -> None:
    """Write AOVs as the channels of one image: the renderer's one image writer.

    The file type comes from the extension (``exr``, ``png``, ``tif``, ...);
    :func:`output_plan` says which AOVs go in and with which pixel types.
    Channel names: color → ``R,G,B``; depth → ``Z``; normal → ``N.x,N.y,N.z``;
    any other AOV ``name.c`` for each channel c. Values a pixel type cannot
    hold (NaN, infinities, beyond half float's range) are clamped, with a
    warning. Every file says ``Software = "mipray <version>"``. The arrays
    are read in place; the GIL is released while writing.

    Args:
        path: output file; missing folders are made.
        aovs: H×W×C float32 arrays, all of the same H and W.
        order: which AOVs to write, in channel order (default: all, as given).
        formats: per-AOV pixel format, ``"half"``, ``"float"`` or ``"uint8"``;
            the file type's default for an AOV not named.
        metadata: extra image attributes: ``str``, ``int`` and ``float`` values,
            and 4×4 matrices given as 16 floats, row by row (``matrix44``).
        color_correction: ``"sRGB"`` (8-bit files hold the color AOV
            sRGB-encoded) or ``"disabled"`` (the values as given, the
            default: this function writes what it is handed;
            ``mipray.image.write_aovs`` defaults to ``"sRGB"``).
        atomic: write a hidden temporary file beside ``path`` and rename it
            over ``path``; it is removed when the write fails.

    Raises:
        OSError: the file cannot be written, an AOV in ``order`` is missing,
            or the path has no extension or an 8-bit type lacks the color AOV.
        ValueError: an array is not H×W×C float32, shapes disagree, or a
            format or color correction mode is unknown.
    """

def output_plan(
    path: str, aovs: list[str], color_correction: str = "sRGB"
) -> tuple[list[str], dict[str, str], bool]:
    """How :func:`write_image` writes ``aovs`` to ``path``.

    Returns:
        ``(order, formats, encode_srgb)``: the AOVs the file holds in channel
        order (8-bit types: ``color``, and ``alpha`` where the type has it),
        each one's pixel type, and whether the color is sRGB-encoded.

    Raises:
        ValueError: no extension, an 8-bit type without the color AOV, or an
            unknown color correction mode; the message names the path.
    """

def eight_bit_aovs(path: str) -> list[str]:
    """The AOVs an 8-bit file at ``path`` holds: color, and alpha where the type has alpha."""

def srgb_encode(linear: NDArray[np.float32]) -> NDArray[np.float32]:
    """The sRGB transfer curve of linear values clamped to [0, 1] (NaN as 0), as written."""

def read_image(path: str) -> tuple[NDArray[np.float32], list[str]]:
    """Read an image through OpenImageIO.

    Returns:
        ``(pixels, channel_names)`` with pixels an H×W×C float32 array.

    Raises:
        OSError: the file cannot be read.
    """

def read_metadata(path: str) -> dict[str, str]:
    """An image's string attributes (``Software``, ``mipray:camera``, ...).

    Raises:
        OSError: the file cannot be read.
    """

def version() -> str:
    """The version of the compiled module, e.g. ``"0.1.0"``."""

def render_settings() -> list[tuple[str, str, str]]:
    """Every render setting the delegate accepts, as ``(key, default, description)``; the
    default is ``""`` for a setting unset unless given (``mipray-record --list-settings``)."""

def settings() -> list[dict[str, Any]]:
    """The settings table, one dict a row: ``key``, ``type`` (``int``, ``float``, ``bool``,
    ``choice``), ``min``, ``max``, ``min_open``, ``max_open`` (numbers; None for a choice),
    ``choices``, ``default`` (None when unset), ``range`` (the values it takes, in words),
    ``help``, ``scope`` (``render``, ``geometryCache``, ``textures``, ``scene``); see
    :class:`mipray.settings.SettingRow`."""

def parse_setting(key: str, value: bool | int | float | str) -> int | float | str:
    """``value`` (a number, or text as typed) checked as setting ``key``'s, as the renderer
    holds it (on/off settings as 0 or 1). Raises ValueError naming the setting, the value and
    the range, or listing the valid keys."""

def aov_names() -> list[str]:
    """Every AOV the delegate can render (README's AOV table says what each holds)."""

def aovs() -> list[dict[str, Any]]:
    """The AOV table, one dict an AOV: ``name``, ``channels``, ``meaning``, ``averaged``,
    ``clear``, ``file_channels``, ``format`` (``"half"`` or ``"float"``); see
    :class:`mipray.aovs.AovRow`."""

def check_trim_curves(trim: Mapping[str, Any]) -> str | None:
    """What is wrong with a NurbsPatch's trim curves (``gprim["trim"]`` of ``set_mesh``:
    ``counts``, ``orders``, ``vertex_counts``, ``knots``, ``ranges``, ``points``), in one line
    naming the ``trimCurve:*`` attribute; None when they trim."""

def subdiv_compare(
    name: str,
    *,
    obj_text: str | None = None,
    points: NDArray[np.float32] | None = None,
    face_vertex_counts: NDArray[np.int32] | None = None,
    face_vertex_indices: NDArray[np.int32] | None = None,
    scheme: str = "catmullClark",
    interpolate_boundary: str = "edgeAndCorner",
    face_varying_linear_interpolation: str = "cornersPlus1",
    triangle_subdivision_rule: str = "catmullClark",
    crease_indices: NDArray[np.int32] | None = None,
    crease_lengths: NDArray[np.int32] | None = None,
    crease_sharpnesses: NDArray[np.float32] | None = None,
    corner_indices: NDArray[np.int32] | None = None,
    corner_sharpnesses: NDArray[np.float32] | None = None,
    hole_indices: NDArray[np.int32] | None = None,
    left_handed: bool = False,
    uniform_level: int = 2,
    samples_per_side: int = 5,
    tessellation_patches: int = 512,
    split_depth: int = 2,
    split_patches: int = 64,
    quick: bool = False,
    table: bool = False,
    heatmap: str | None = None,
    heatmap_rate: int = 4,
) -> str:
    """Compare a mesh's subdivision surface with OpenSubdiv's.

    The mesh is an OBJ in OpenSubdiv's regression-shape format (``obj_text``)
    or USD's mesh attributes, as ``RenderDelegate.set_mesh`` takes them.

    Returns:
        The report as one JSON object (see docs/subdivision-compare.md), or a
        readable table with ``table=True``.

    Raises:
        ValueError: the mesh is refused, naming it ("not supported" for
            hierarchical edits), or the heatmap cannot be written.
    """
