"""Mesh data is checked once, by the compiled delegate's ``set_mesh``: what it refuses is a
``PrimDataError`` (a ``PrimError``, so a ``MiprayError``, and a ``ValueError``) naming the
prim, the mesh is not kept, and the scene delegate reads a bad mesh without checking it.

The truths are the USD attributes' own values (the bad index, the face count) and Python's
repr of the bad point, not the renderer's code.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Usd

from mipray.errors import MiprayError, PrimDataError, PrimError
from mipray.usd.mesh import mesh_arguments

from stages import CUBE_COUNTS, CUBE_INDICES, CUBE_POINTS, add_cube, new_stage


def cube_args(**changes: object) -> dict:
    args = {
        "points": np.array(CUBE_POINTS, np.float32),
        "face_vertex_counts": np.array(CUBE_COUNTS, np.int32),
        "face_vertex_indices": np.array(CUBE_INDICES, np.int32),
        "transform": np.eye(4),
    }
    args.update(changes)
    return args


def test_the_delegate_refuses_bad_mesh_data_as_a_prim_data_error(native) -> None:
    delegate = native.RenderDelegate()
    nan_point = np.array(CUBE_POINTS, np.float32)
    nan_point[3, 1] = np.nan
    faces = len(CUBE_COUNTS)
    cases = [
        (
            cube_args(points=nan_point),
            f"points[3] = {tuple(float(c) for c in nan_point[3])} is not finite",
        ),
        (
            cube_args(hole_indices=np.array([faces], np.int32)),
            f"holeIndices[0] = {faces} is out of range for {faces} faces",
        ),
        (
            cube_args(face_vertex_counts=np.array([*CUBE_COUNTS[:-1], 3], np.int32)),
            f"faceVertexCounts add up to {sum(CUBE_COUNTS) - 1} but faceVertexIndices has "
            f"{len(CUBE_INDICES)} entries",
        ),
        (cube_args(transform=np.full((4, 4), math.inf)), "transform is not finite"),
        (cube_args(scheme="loop"), "subdivisionScheme loop needs triangles, but face 0 has 4"),
    ]
    for args, reason in cases:
        with pytest.raises(PrimDataError) as caught:
            delegate.set_mesh("/World/Bad", **args)
        error = caught.value
        assert isinstance(error, PrimError) and isinstance(error, MiprayError)
        assert isinstance(error, ValueError)
        assert error.prim_path == "/World/Bad"
        assert error.reason.startswith(reason), error.reason
        assert str(error) == f"/World/Bad: {error.reason}"
        assert "/World/Bad" not in delegate.prim_paths(), "a refused mesh is not kept"
    delegate.set_mesh("/World/Bad", **cube_args())
    assert delegate.prim_paths() == ["/World/Bad"]


def test_the_scene_delegate_leaves_the_checking_to_the_delegate() -> None:
    stage = new_stage()
    mesh = add_cube(stage, "/World/Bad", indices=[*CUBE_INDICES[:-1], 99])
    args = mesh_arguments(mesh, Usd.TimeCode.Default(), np.eye(4))
    assert args is not None and int(args["face_vertex_indices"][-1]) == 99
