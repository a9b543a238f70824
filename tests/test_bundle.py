import json

import numpy as np
import pytest
import torch
from helpers import make_bundle

from facegen.bundle import load_bundle, read_metadata, save_bundle
from facegen.errors import FacegenError


def test_round_trip_keeps_weights_template_and_metadata(tmp_path, grid_mesh):
    b = make_bundle(grid_mesh, tmp_path / "m.safetensors")
    back = load_bundle(tmp_path / "m.safetensors")
    for k, v in b.model.state_dict().items():
        assert torch.equal(v, back.model.state_dict()[k]), k
    assert np.array_equal(back.template.vertices, grid_mesh.vertices)
    assert np.array_equal(back.template.faces, grid_mesh.faces)
    assert set(back.template.regions) == {"lips", "upper_face"}
    assert back.speakers == ["F2", "F3", "M3"] and back.text_backend == "minilm"
    meta = read_metadata(tmp_path / "m.safetensors")
    assert meta["format_version"] == 1
    assert meta["topology"]["num_vertices"] == 120 and len(meta["topology"]["fingerprint"]) == 16
    assert meta["model_config"]["fusion"] == "tensor" and meta["feature_config"]["n_mels"] == 128
    # no pickle: the file is a plain safetensors header + raw data
    header_len = int.from_bytes((tmp_path / "m.safetensors").read_bytes()[:8], "little")
    header = json.loads((tmp_path / "m.safetensors").read_bytes()[8:8 + header_len])
    assert "facegen" in header["__metadata__"]


def test_half_precision_bundle_is_smaller_and_close(tmp_path, grid_mesh):
    b = make_bundle(grid_mesh)
    save_bundle(b, tmp_path / "f32.safetensors")
    save_bundle(b, tmp_path / "f16.safetensors", precision="fp16")
    weight_bytes = sum(v.numel() * 4 for v in b.model.state_dict().values() if v.is_floating_point())
    saved = (tmp_path / "f32.safetensors").stat().st_size - (tmp_path / "f16.safetensors").stat().st_size
    assert abs(saved - weight_bytes / 2) < 0.01 * weight_bytes
    h = load_bundle(tmp_path / "f16.safetensors")
    w, w16 = b.model.fc_out.weight, h.model.fc_out.weight
    assert w16.dtype == torch.float32 and torch.allclose(w, w16, atol=1e-3, rtol=1e-3)


def test_speaker_lookup(grid_mesh):
    b = make_bundle(grid_mesh)
    assert b.speaker_index("M3") == 2 and b.speaker_index("1") == 1 and b.speaker_index(None) == 0
    with pytest.raises(FacegenError, match="0=F2, 1=F3, 2=M3"):
        b.speaker_index("F9")
    with pytest.raises(FacegenError):
        b.speaker_index(7)


def test_corrupt_truncated_and_foreign_files(tmp_path, grid_mesh):
    make_bundle(grid_mesh, tmp_path / "m.safetensors")
    data = (tmp_path / "m.safetensors").read_bytes()
    (tmp_path / "trunc.safetensors").write_bytes(data[: len(data) // 2])
    (tmp_path / "junk.safetensors").write_bytes(b"\x00garbage" * 10)
    with pytest.raises(FacegenError, match="corrupt or truncated"):
        load_bundle(tmp_path / "trunc.safetensors")
    with pytest.raises(FacegenError, match="is not a model bundle") as info:  # not even a safetensors file
        load_bundle(tmp_path / "junk.safetensors")
    assert info.value.param == "bundle"
    from safetensors.torch import save_file

    save_file({"x": torch.zeros(2)}, str(tmp_path / "other.safetensors"))
    with pytest.raises(FacegenError, match="not a facegen bundle"):
        load_bundle(tmp_path / "other.safetensors")
    with pytest.raises(FacegenError, match="does not exist"):
        load_bundle(tmp_path / "missing.safetensors")


def test_biwi_sized_bundle(tmp_path, biwi_template):
    b = make_bundle(biwi_template, tmp_path / "b.safetensors")
    back = load_bundle(b.path)
    assert back.template.num_vertices == 23370 and back.template.faces.shape == (46068, 3)
    assert len(back.template.regions["lips"]) == 4996


def test_int8_bundle_quarter_size_and_close(tmp_path, biwi_template):
    b = make_bundle(biwi_template, small=False)
    save_bundle(b, tmp_path / "f32.safetensors")
    save_bundle(b, tmp_path / "i8.safetensors", precision="int8")
    size32 = (tmp_path / "f32.safetensors").stat().st_size
    size8 = (tmp_path / "i8.safetensors").stat().st_size
    assert size8 < 0.3 * size32
    back = load_bundle(tmp_path / "i8.safetensors")
    w, wq = b.model.fc_out.weight, back.model.fc_out.weight
    row_max = w.abs().amax(1, keepdim=True)
    assert torch.all((w - wq).abs() <= row_max / 254 + 1e-7)
    assert read_metadata(tmp_path / "i8.safetensors")["weights_precision"] == "int8"
    with pytest.raises(FacegenError, match="unknown precision"):
        save_bundle(b, tmp_path / "x.safetensors", precision="int4")
