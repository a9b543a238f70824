import numpy as np
import pytest

from facegen.errors import FacegenError
from facegen.face.mesh import Mesh, check_topology, read_mesh, read_region, write_mesh, write_region


@pytest.mark.parametrize("ext", ["ply", "obj"])
def test_write_read_keeps_order(tmp_path, grid_mesh, ext):
    write_mesh(grid_mesh, tmp_path / f"m.{ext}")
    back = read_mesh(tmp_path / f"m.{ext}")
    assert np.allclose(back.vertices, grid_mesh.vertices, atol=1e-6)
    assert np.array_equal(back.faces, grid_mesh.faces)


def test_biwi_reads_exactly(biwi_template):
    assert biwi_template.vertices.shape == (23370, 3) and biwi_template.faces.shape == (46068, 3)
    assert biwi_template.faces[0].tolist() == [5852, 105, 22]
    assert len(biwi_template.regions["upper_face"]) == 7784


def test_topology_checks(grid_mesh):
    check_topology(grid_mesh, 120, grid_mesh.faces, "t")
    with pytest.raises(FacegenError, match="has 119 vertices but the model expects 120"):
        check_topology(Mesh(grid_mesh.vertices[:-1], grid_mesh.faces), 120, grid_mesh.faces, "t")
    swapped = grid_mesh.faces.copy()
    swapped[0] = swapped[0, ::-1]
    with pytest.raises(FacegenError, match="different face list"):
        check_topology(Mesh(grid_mesh.vertices, swapped), 120, grid_mesh.faces, "t")


def test_nan_and_bad_files_refused(tmp_path, grid_mesh):
    bad = Mesh(grid_mesh.vertices.copy(), grid_mesh.faces)
    bad.vertices[3, 1] = np.nan
    write_mesh(bad, tmp_path / "nan.obj")
    with pytest.raises(FacegenError, match="NaN"):
        read_mesh(tmp_path / "nan.obj")
    (tmp_path / "x.stl").write_text("solid")
    with pytest.raises(FacegenError, match="not .ply or .obj"):
        read_mesh(tmp_path / "x.stl")
    with pytest.raises(FacegenError, match="does not exist"):
        read_mesh(tmp_path / "none.ply")


def test_region_files(tmp_path):
    write_region(np.array([3, 1, 2]), tmp_path / "r.txt")
    assert (tmp_path / "r.txt").read_text() == "3, 1, 2\n"
    assert read_region(tmp_path / "r.txt").tolist() == [3, 1, 2]
