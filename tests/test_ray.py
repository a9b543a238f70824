"""`facegen batch --engine ray`: a local Ray instance on 127.0.0.1 runs a manifest as actor tasks and writes
the same files as the local engine; an unreachable cluster is one line and exit 2. Skipped without Ray."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from helpers import grid_face, make_bundle

from facegen.batch_run import run_manifest

ray = pytest.importorskip("ray")

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cluster():
    """A local Ray instance bound to the loopback interface, 2 CPUs, no dashboard; shut down after."""
    if ray.is_initialized():
        pytest.skip("a Ray instance is already running in this process")
    ray.init(num_cpus=2, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": str(REPO)}})
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def batch_inputs(tmp_path_factory):
    from facegen.espeak import synthesize

    folder = tmp_path_factory.mktemp("ray")
    for i, sentence in enumerate(("Such expensive furnishings!", "What an excellent room you have, sir.")):
        sf.write(folder / f"s{i}.wav", synthesize(sentence, pitch=50 + 10 * i, sample_rate=16000).audio,
                 16000,
                 subtype="PCM_16")
    model = folder / "small.safetensors"
    make_bundle(grid_face(12, 10, height=0.8, bend=2.0), model, modalities="audio", speakers=("F2", "M3"))
    manifest = folder / "lines.csv"
    manifest.write_text("audio,speaker,output\ns0.wav,F2,s0.npy\ns1.wav,M3,sub/s1.npy\nmissing.wav,,m.npy\n")
    return manifest, model


def test_ray_engine_writes_what_the_local_engine_writes(cluster, batch_inputs, tmp_path):
    manifest, model = batch_inputs
    on_ray = run_manifest(manifest, tmp_path / "ray", engine="ray", formats="npy,usda", model=model,
                          device="cpu")
    local = run_manifest(manifest, tmp_path / "local", jobs=1, formats="npy,usda", model=model, device="cpu")
    assert [r.status for r in on_ray.results] == [r.status for r in local.results] == ["passed", "passed",
                                                                                       "error"]
    assert ray.is_initialized()  # the engine used this process's instance and left it running
    for name in ("s0.npy", "sub/s1.npy"):
        a, b = np.load(tmp_path / "ray" / name), np.load(tmp_path / "local" / name)
        assert a.shape == b.shape and a.shape[1] == 3 * 120
        assert np.abs(a - b).max() < 1e-6
        assert (tmp_path / "ray" / name).with_suffix(".usda").is_file()
        assert (tmp_path / "ray" / name).with_suffix(".wav").read_bytes() == \
            (tmp_path / "local" / name).with_suffix(".wav").read_bytes()
    report = json.loads((tmp_path / "ray" / "report.json").read_text())
    assert report["run"]["engine"] == "ray" and report["summary"]["passed"] == 2
    assert all(v["ok"] for item in report["items"][:2] for v in item["validation"])
    suite = ET.parse(tmp_path / "ray" / "report.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("errors")) == ("3", "1")
    again = run_manifest(manifest, tmp_path / "ray", engine="ray", formats="npy,usda", model=model,
                         device="cpu")
    assert [r.status for r in again.results] == ["skipped", "skipped", "error"]


def test_unreachable_ray_address_is_one_line_exit_2(batch_inputs, tmp_path):
    manifest, model = batch_inputs
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.run([sys.executable, "-m", "facegen", "batch", str(manifest), "-o",
                           str(tmp_path / "out"),
                           "-m", str(model), "--engine", "ray", "--ray-address", f"127.0.0.1:{port}"],
                          capture_output=True, text=True, timeout=300, cwd=REPO, check=False)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "cannot reach the Ray cluster at 127.0.0.1" in proc.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("server", ["silent", "http"])
def test_an_address_that_is_not_ray_is_one_line_exit_2(batch_inputs, tmp_path, server):
    """Something listens there, but not Ray (a silent TCP server, an HTTP port): refused at once, where Ray's
    own client would retry for minutes (no timing assert: the process timeout below catches a hang)."""
    import http.server
    import threading

    manifest, model = batch_inputs
    if server == "http":
        httpd = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
        port = httpd.server_address[1]
        threading.Thread(target=httpd.serve_forever, daemon=True).start()
        listener = httpd.socket
    else:
        listener = socket.socket()
        listener.bind(("127.0.0.1", 0))
        listener.listen(8)
        port = listener.getsockname()[1]
    try:
        proc = subprocess.run([sys.executable, "-m", "facegen", "batch", str(manifest), "-o",
                               str(tmp_path / "out"), "-m", str(model), "--engine", "ray", "--ray-address",
                               f"127.0.0.1:{port}"], capture_output=True, text=True, timeout=60, cwd=REPO,
                              check=False)
    finally:
        if server == "http":
            httpd.shutdown()
        listener.close()
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "not as a Ray cluster" in proc.stderr, proc.stderr
    assert not (tmp_path / "out").exists()
