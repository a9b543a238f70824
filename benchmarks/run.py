"""`make bench`: facegen's speed and memory on this machine, side by side with a FaceFormer-class encoder.

Measures, and writes benchmarks/RESULTS.md (with the machine: CPU, cores, RAM, threads, versions, load):

- `facegen --help` and `facegen animate` as new processes on synthesised speech of 5 s and 60 s (.usdc
  out, default model), with each stage's share from FACEGEN_PROFILE=1 (start-up/imports, model load,
  alignment, text model, features, inference, writing), real-time factor and peak RSS of the child;
- the model forward alone (decoder states + every output frame) for the same clips, with variants
  (one-pass torch forward, torch/MKL blocks, threads), against transformers' Wav2Vec2Model with the base
  config and random weights (the audio encoder FaceFormer and CodeTalker build on), on the same audio;
- a 10-minute clip animated into .npy through the streaming path (peak RSS, time per audio minute),
  and the peak RSS of the in-memory path into .usdc for 3 minutes;
- .usdc and .glb writing throughput (bench_export.py) and training sequences per second (bench_train.py).

    python benchmarks/run.py [--quick] [--no-long] [--no-train] [--out benchmarks/RESULTS.md]
"""

from __future__ import annotations

import os

# as bench_train.py: spinning OpenMP threads on busy cores
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse
import json
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
BIWI = REPO.parent / "shared" / "biwi" / "BIWI.ply"
FPS = 25.0
# issue 13: a 5 s clip -> .usdc in a new process <= 2.5 s, a one-minute recording <= 6 s
TARGETS = {"forward_x_realtime": 100.0, "animate_5s_wall": 2.5, "animate_60s_wall": 6.0, "help_wall": 0.5,
           "long_rss_mb": 2048.0}
BLOCK_VARIANTS = (128, 256, 1024)  # output blocks timed besides the default (facegen.inference.BLOCK_FRAMES)
STAGES = ("start-up", "model_load", "audio", "alignment", "text_model_load", "text_features",
          "audio_features",
          "inference", "writing", "exit")


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------------------
# machine


def machine() -> dict:
    import torch

    info = {"python": platform.python_version(), "platform": platform.platform()}
    try:
        cpuinfo = Path("/proc/cpuinfo").read_text()
        info["cpu"] = re.search(r"model name\s*:\s*(.*)", cpuinfo).group(1).strip()
        flags = re.search(r"flags\s*:\s*(.*)", cpuinfo).group(1).split()
        info["simd"] = " ".join(f for f in ("avx2", "avx512f", "avx512_bf16", "avx512_vnni", "amx_tile")
                                if f in flags)
        mem = Path("/proc/meminfo").read_text()
        info["ram_gb"] = round(int(re.search(r"MemTotal:\s+(\d+)", mem).group(1)) / 2**20, 1)
    except (OSError, AttributeError):
        info["cpu"] = platform.processor()
    info["cores"] = os.cpu_count()
    info["torch_threads"] = torch.get_num_threads()
    info["omp_wait_policy"] = os.environ.get("OMP_WAIT_POLICY", "")
    versions = {"torch": torch.__version__, "numpy": np.__version__}
    for module in ("transformers", "pocketsphinx", "safetensors", "soundfile"):
        try:
            versions[module] = __import__(module).__version__
        except (ImportError, AttributeError):
            pass
    try:
        from pxr import Usd

        versions["usd"] = ".".join(map(str, Usd.GetVersion()))
    except ImportError:
        pass
    from facegen import __version__

    versions["facegen"] = __version__
    info["versions"] = versions
    try:
        from threadpoolctl import threadpool_info

        info["blas"] = ", ".join(f"{p['internal_api']} {p.get('version') or ''} "
                                 f"{p.get('architecture') or ''}".strip()
                                 for p in threadpool_info() if p["user_api"] == "blas")
    except ImportError:
        pass
    info["load_average"] = [round(x, 2) for x in os.getloadavg()]
    return info


def busy_processes() -> list[str]:
    """Other processes using a lot of CPU now (the numbers are pessimistic when there are any)."""
    try:
        out = subprocess.run(["ps", "-eo", "pid,pcpu,args", "--sort=-pcpu"], capture_output=True, text=True,
                             check=False).stdout.splitlines()[1:6]
    except OSError:
        return []
    return [line.strip()[:100] for line in out if float(line.split()[1]) > 20
            and str(os.getpid()) != line.split()[0]]


# --------------------------------------------------------------------------------------------------
# inputs


def make_clip(folder: Path, seconds: float, name: str) -> tuple[Path, Path, float]:
    """Synthesised speech of about `seconds` (whole sentences, 0.3 s pauses) at 16 kHz, and its transcript."""
    import soundfile as sf

    from facegen.espeak import synthesize
    from facegen.synth.sentences import SENTENCES

    sentences = list(SENTENCES.values())
    if seconds < 10:  # one sentence, spoken at the rate that makes it last `seconds`
        rate = 170
        for _ in range(3):
            s = synthesize(sentences[0], sample_rate=16000, pitch=45, rate=rate)
            rate = int(np.clip(rate * len(s.audio) / 16000 / seconds, 80, 450))
        samples, text = s.audio, [sentences[0]]
    else:  # whole sentences with 0.3 s pauses, voices varied
        audio, text, total, i = [], [], 0.0, 0
        while total < seconds - 0.5:
            s = synthesize(sentences[i % len(sentences)], sample_rate=16000, pitch=40 + 5 * (i % 5))
            audio += [s.audio, np.zeros(int(0.3 * 16000), np.float32)]
            text.append(sentences[i % len(sentences)])
            total += len(s.audio) / 16000 + 0.3
            i += 1
        samples = np.concatenate(audio)
    wav, txt = folder / f"{name}.wav", folder / f"{name}.txt"
    sf.write(wav, samples, 16000, subtype="PCM_16")
    txt.write_text(" ".join(text) + "\n")
    return wav, txt, len(samples) / 16000


def model_path(folder: Path) -> tuple[Path, str]:
    """The built-in default model, or a paper-sized random bundle (int8, like the default) when absent."""
    from facegen.bundle import default_bundle_path

    default = default_bundle_path()
    if default.is_file():
        return default, f"built-in default model ({default.stat().st_size / 1e6:.1f} MB)"
    sys.path.insert(0, str(REPO / "tests"))
    from bundles import make_bundle

    from facegen.bundle import save_bundle

    if BIWI.is_file():
        from facegen.face.mesh import read_mesh

        template, where = read_mesh(BIWI), "BIWI template"
    else:
        from facegen.face.procedural import make_face

        template, where = make_face(), "procedural face"
    bundle = make_bundle(template, None, small=False, speakers=("F2", "F3", "F4", "M3", "M4", "M5"))
    path = folder / "model.safetensors"
    save_bundle(bundle, path, precision="int8")
    return path, f"stand-in: paper-sized network, random weights, int8, {where} (no default model yet)"


# --------------------------------------------------------------------------------------------------
# new processes


def run_child(args: list[str], env: dict | None = None, timeout: float = 1800) -> dict:
    """Run a command with FACEGEN_PROFILE=1; wall time, the profile JSON (if printed), return code."""
    env = {**os.environ, "FACEGEN_PROFILE": "1", **(env or {})}
    start = time.time()
    proc = subprocess.run(args, capture_output=True, text=True, env=env, timeout=timeout, check=False)
    wall = time.time() - start
    profile = None
    for line in reversed(proc.stderr.strip().splitlines()):
        if line.startswith('{"facegen_profile"'):
            profile = json.loads(line)
            break
    if proc.returncode != 0:
        log(f"  command failed ({proc.returncode}): {' '.join(args)}\n{proc.stderr[-2000:]}")
    return {"wall": wall, "start": start, "profile": profile, "returncode": proc.returncode,
            "stdout": proc.stdout}


def facegen_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "facegen", *map(str, args)]


def time_help(runs: int) -> dict:
    walls = [run_child(facegen_cmd("--help"))["wall"] for _ in range(runs)]
    return {"median": statistics.median(walls), "best": min(walls)}


def stages_of(run: dict) -> dict:
    prof = run["profile"] or {}
    stages = dict(prof.get("facegen_profile", {}))
    marks = prof.get("marks", {})
    if "animate_start" in marks:
        stages["start-up"] = marks["animate_start"] - run["start"]
    # the rest: mostly interpreter teardown at exit ("alignment_in_parallel" ran in another process, beside
    # these)
    stages["exit"] = run["wall"] - sum(v for k, v in stages.items() if not k.endswith("_in_parallel"))
    return stages


def time_animate(wav: Path, txt: Path, model: Path, out: Path, runs: int) -> dict:
    results = []
    for _ in range(runs):
        r = run_child(facegen_cmd("animate", wav, "--text-file", txt, "-m", model, "--device", "cpu", "-q",
                                  "-o", out))
        if r["returncode"] != 0:
            raise SystemExit(f"facegen animate failed on {wav}")
        r["bytes"] = out.stat().st_size
        for written in {out, out.with_suffix(".wav")} - {wav}:  # each run writes a new file, as a user's run
            written.unlink(missing_ok=True)  # does (the sidecar of clip.usdc is the input clip.wav: kept)
        results.append(r)
    best = min(results, key=lambda r: r["wall"])
    return {"wall": best["wall"], "median": statistics.median(r["wall"] for r in results),
            "stages": stages_of(best), "rss_mb": (best["profile"] or {}).get("max_rss_mb"),
            "modules": (best["profile"] or {}).get("heavy_modules", []), "bytes": best["bytes"]}


def import_profile() -> list[tuple[str, float]]:
    """The slowest top-level imports of `facegen.animator` in a new process (python -X importtime)."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", "import facegen.cli, facegen.animator"],
                          capture_output=True, text=True, check=False)
    packages: dict[str, tuple[int, float]] = {}  # package -> (indent, cumulative s) where first imported
    for line in proc.stderr.splitlines():
        m = re.match(r"import time:\s+\d+ \|\s+(\d+) \|( *)(\S+)", line)
        if not m or m.group(3).startswith("_"):
            continue
        root = m.group(3).split(".")[0] if not m.group(3).startswith("facegen") else m.group(3)
        depth, seconds = len(m.group(2)), int(m.group(1)) / 1e6
        if root not in packages or depth < packages[root][0]:
            packages[root] = (depth, seconds)
    rows = sorted(((k, v[1]) for k, v in packages.items() if not k.startswith("facegen")),
                  key=lambda r: -r[1])
    heavy = sorted(k for k in packages if k in ("librosa", "numba", "transformers", "pxr", "scipy",
                                                "sklearn"))
    return rows[:5] + [(("(imported among them: "
                         f"{', '.join(heavy) or 'none of librosa, numba, transformers, pxr'})"),
                        0.0)]


# --------------------------------------------------------------------------------------------------
# forward in this process


def best_of(fn, runs: int) -> float:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def forward_times(model: Path, clips: dict[str, tuple[Path, Path, float]], runs: int) -> dict:
    """Seconds of our whole model forward (decoder states + all frames) and of wav2vec2-base, per clip."""
    import torch
    from transformers import Wav2Vec2Config, Wav2Vec2Model

    from facegen.bundle import load_bundle

    bundle = load_bundle(model)
    torch.manual_seed(0)
    w2v = Wav2Vec2Model(Wav2Vec2Config()).eval()
    out = {}
    for name, (wav, _, seconds) in clips.items():
        out[name] = forward_clip(bundle, w2v, wav, seconds, runs)
        log(f"  forward {name}: ours {out[name]['ours']:.3f} s, wav2vec2-base "
            f"{out[name]['wav2vec2_base']:.2f} s")
    return out


def forward_clip(bundle, w2v, wav: Path, seconds: float, runs: int) -> dict:
    import torch
    from threadpoolctl import threadpool_limits

    from facegen.audio import load_audio, mel_features
    from facegen.inference import BLOCK_FRAMES, decoder_states, frame_stream
    from facegen.model import one_hot
    from facegen.phonetics import silence

    samples, sr = load_audio(wav)
    mel = mel_features(samples, sr, bundle.features, bundle.mel_filters)
    T = len(mel)
    text = np.random.default_rng(0).normal(0, 0.3, (T, bundle.config.text_dim)).astype(np.float32)
    template = bundle.template.vertices
    buffer = np.empty((T, template.shape[0], 3), np.float32)

    def ours(block: int = BLOCK_FRAMES) -> None:
        frames = frame_stream(bundle, decoder_states(bundle, mel, text, 0), template, block)
        for s in range(0, T, block):
            frames.compute(s, min(s + block, T), out=buffer[s:s + block])

    phones = torch.from_numpy(silence(T))[None] if bundle.config.n_phones else None  # a phone stream's input

    def one_pass() -> None:
        with torch.inference_mode():
            offsets = bundle.model(torch.from_numpy(mel)[None], torch.from_numpy(text)[None],
                                   one_hot(0, bundle.config.num_speakers), phones=phones)
            _ = template[None] + offsets[0].numpy()

    def torch_blocks(block: int = BLOCK_FRAMES) -> None:
        states = decoder_states(bundle, mel, text, 0)
        fc = bundle.model.fc_out
        flat = torch.from_numpy(buffer.reshape(T, -1))
        with torch.inference_mode():
            base = fc.bias + torch.from_numpy(template.reshape(-1))
            for s in range(0, T, block):
                torch.addmm(base, states[s:s + block], fc.weight.T, out=flat[s:s + block])

    ours()  # warm-up (allocations, oneDNN primitives)
    fewer = max(1, runs - 1)
    row = {"frames": T, "seconds": seconds, "ours": best_of(ours, runs),
           "states_only": best_of(lambda: decoder_states(bundle, mel, text, 0), runs),
           "one_pass_torch": best_of(one_pass, fewer), "torch_mkl_blocks": best_of(torch_blocks, fewer)}
    for block in BLOCK_VARIANTS:
        row[f"ours_block_{block}"] = best_of(lambda b=block: ours(b), fewer)
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        with threadpool_limits(1):
            row["ours_1_thread"] = best_of(ours, fewer)
    finally:
        torch.set_num_threads(threads)
    audio16 = torch.from_numpy(np.ascontiguousarray(samples, np.float32))[None]
    with torch.inference_mode():
        w2v(audio16[:, :16000])  # warm-up
        row["wav2vec2_base"] = best_of(lambda: w2v(audio16), 2 if seconds < 10 else 1)
    return row


# --------------------------------------------------------------------------------------------------
# long audio

LONG_SCRIPT = """
import json, sys, time
import numpy as np
from facegen import animate
from facegen.runtime import PROFILE, peak_rss_mb
wav, txt, model, out = sys.argv[1:5]
t0 = time.perf_counter()
anim = animate(wav, text=open(txt).read(), bundle=model, device="cpu", stream=True)
frames = anim.vertices
T, V, _ = frames.shape
with PROFILE.stage("writing"), open(out, "wb") as f:  # .npy [T, 3V], block by block
    np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": (T, 3 * V)})
    for _, block in frames.blocks():
        f.write(block.data)
print(json.dumps({"seconds": time.perf_counter() - t0, "frames": T, "rss_mb": peak_rss_mb(),
                  "stages": PROFILE.stages, "output_mb": frames.nbytes / 2**20}))
"""


def time_long(folder: Path, clip: tuple[Path, Path, float], model: Path) -> dict:
    script = folder / "long.py"
    script.write_text(LONG_SCRIPT)
    out = folder / f"{clip[0].stem}.npy"
    r = run_child([sys.executable, str(script), str(clip[0]), str(clip[1]), str(model), str(out)])
    if r["returncode"] != 0:
        return {"error": "failed"}
    result = json.loads(r["stdout"].strip().splitlines()[-1])
    result["wall"] = r["wall"]
    out.unlink()
    return result


# --------------------------------------------------------------------------------------------------
# writers and training (the benchmarks beside this one)


def writing_throughput(folder: Path) -> dict:
    """.usdc (points) and .glb (bench_export.py) writing of a 60 s, 1500-frame animation."""
    sys.path.insert(0, str(HERE))
    import bench_export

    from facegen.exchange import write_animation

    anim, _ = bench_export.animation(argparse.Namespace(npy=None, seconds=60.0, fps=FPS))
    out = folder / "minute.usdc"
    usdc = best_of(lambda: write_animation(anim, out), 2)
    result = {"frames": anim.num_frames, "usdc_seconds": usdc, "usdc_mb": out.stat().st_size / 1e6}
    proc = subprocess.run([sys.executable, str(HERE / "bench_export.py"), "--runs", "2"], capture_output=True,
                          text=True, check=False, timeout=900)
    for line in proc.stdout.splitlines():
        if line.startswith('{"benchmark": "glb_export"'):
            glb = json.loads(line)
            result.update(glb_seconds=glb["best_seconds"], glb_mb=glb["bytes"] / 1e6)
    return result


def training_speed(sequences: int) -> dict:
    proc = subprocess.run([sys.executable, str(HERE / "bench_train.py"), "--sequences", str(sequences)],
                          capture_output=True, text=True, check=False, timeout=1800)
    m = re.search(r"seconds/epoch ([\d.]+)\s+sequences/s ([\d.]+)", proc.stdout)
    if not m:
        log(f"  bench_train.py failed:\n{proc.stdout[-1000:]}{proc.stderr[-1000:]}")
        return {}
    return {"sequences": sequences, "seconds_per_epoch": float(m.group(1)),
            "sequences_per_s": float(m.group(2))}


# --------------------------------------------------------------------------------------------------
# report


def fmt(x: float | None, digits: int = 2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def report(r: dict) -> str:
    m = r["machine"]
    lines = ["# facegen benchmarks", "",
             f"Run {r['date']} by `make bench` (benchmarks/run.py) in {r['total_seconds']:.0f} s.", "",
             "## Machine", "",
             f"- CPU: {m.get('cpu')} ({m.get('simd', '')}), {m['cores']} cores, {m.get('ram_gb')} GB RAM",
             (f"- torch threads {m['torch_threads']}, OMP_WAIT_POLICY={m['omp_wait_policy'] or 'unset'}, "
              f"BLAS: {m.get('blas', '?')}"),
             "- " + ", ".join(f"{k} {v}" for k, v in m["versions"].items()) + f", Python {m['python']}",
             f"- load average at start {m['load_average']}"
             + (f"; busy processes at start: {'; '.join(r['busy'])} (numbers are pessimistic)" if r["busy"]
                else
                " (machine otherwise idle)"),
             f"- model: {r['model']}", ""]
    lines += ["## Targets", "", "| target | measured | met |", "|---|---|---|"]
    for name, value, target, ok in r["targets"]:
        lines.append(f"| {name} | {value} | {'yes' if ok else 'NO'} (target {target}) |")
    lines += ["", "## `facegen animate` as a new process (.usdc out, best of runs)", "",
              "| clip | audio s | frames | wall s | x real time | peak RSS MB | "
              + " | ".join(STAGES) + " |", "|" + "---|" * (6 + len(STAGES))]
    for name, a in r["animate"].items():
        st = a["stages"]
        shares = [f"{st.get(s, 0):.2f} ({100 * st.get(s, 0) / a['wall']:.0f}%)" for s in STAGES]
        lines.append(f"| {name} | {a['audio_seconds']:.1f} | {a['frames']} | {a['wall']:.2f} | "
                     f"{a['audio_seconds'] / a['wall']:.1f} | {fmt(a['rss_mb'], 0)} | " + " | ".join(shares)
                     + " |")
    lines += ["", ("Stages from FACEGEN_PROFILE=1; start-up = process start to `animate()` (Python, click, "
              "torch imports); writing = from `animate()` returning to the profile printed at exit (pxr "
              "import, the file); exit = the rest of the wall time (interpreter teardown of "
              "torch/transformers modules)."), "",
              f"`facegen --help`: {r['help']['median']:.2f} s (median of runs).", "",
              "Slowest imports at start-up "
              "(`python -X importtime -c 'import facegen.cli, facegen.animator'`): "
              + ", ".join(f"{n} {s:.2f} s" if s else n for n, s in r["imports"]) + ".", ""]
    lines += ["## Model forward vs. a FaceFormer-class encoder (this process, best of runs, seconds)", "",
              ("Ours = the whole network: encoders, fusion, BiLSTMs and every output frame (template + "
               "offsets, float32 [T, 23370, 3]), as facegen.inference runs it: decoder states on one torch "
               "thread, output blocks of 512 frames on numpy's BLAS (2 threads). wav2vec2-base = "
               "transformers' `Wav2Vec2Model(Wav2Vec2Config())`, random weights, on the same 16 kHz audio: "
               "only the audio encoder of FaceFormer/CodeTalker (their decoders come on top)."), "",
              ("| clip | frames | ours | x real time | states only | one-pass torch forward | torch/MKL "
               "output blocks | blocks of 128 / 256 / 1024 | 1 thread | wav2vec2-base | wav2vec2 / ours |"),
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, f in r["forward"].items():
        blocks = " / ".join(f"{f[f'ours_block_{b}']:.3f}" for b in BLOCK_VARIANTS)
        lines.append(f"| {name} | {f['frames']} | {f['ours']:.3f} | {f['seconds'] / f['ours']:.0f} | "
                     f"{f['states_only']:.3f} | {f['one_pass_torch']:.3f} | {f['torch_mkl_blocks']:.3f} | "
                     f"{blocks} | {f['ours_1_thread']:.3f} | {f['wav2vec2_base']:.2f} | "
                     f"**{f['wav2vec2_base'] / f['ours']:.1f}x** |")
    if r.get("long"):
        lines += ["", "## Long audio", "", ("| clip | audio s | frames | wall s | s per audio minute | peak "
                                            "RSS MB | vertices MB | path | stages |"),
                  "|---|---|---|---|---|---|---|---|---|"]
        for name, x in r["long"].items():
            if "error" in x:
                lines.append(f"| {name} | failed |")
                continue
            stages = ", ".join(f"{k} {v:.1f}" for k, v in x.get("stages", {}).items())
            lines.append(f"| {name} | {x['audio_seconds']:.0f} | {x['frames']} | {x['wall']:.1f} | "
                         f"{60 * x['wall'] / x['audio_seconds']:.1f} | {fmt(x['rss_mb'], 0)} | "
                         f"{x.get('output_mb', 0):.0f} | {x['path']} | {stages} |")
    if r.get("writing"):
        w = r["writing"]
        lines += ["", "## Writing and training", "",
                  (f"- .usdc (points, {w['frames']} frames of 23,370 vertices): {w['usdc_seconds']:.2f} s = "
                   f"{w['frames'] / w['usdc_seconds']:.0f} frames/s, {w['usdc_mb'] / w['usdc_seconds']:.0f} "
                   f"MB/s ({w['usdc_mb']:.0f} MB)")]
        if "glb_seconds" in w:
            lines.append(f"- .glb (bench_export.py, PCA morph targets at 1e-3): {w['glb_seconds']:.2f} s = "
                         f"{w['frames'] / w['glb_seconds']:.0f} frames/s ({w['glb_mb']:.1f} MB)")
    if r.get("train"):
        t = r["train"]
        lines.append(f"- training (bench_train.py, {t['sequences']} BIWI-sized sequences, 2 threads): "
                     f"{t['sequences_per_s']:.2f} sequences/s ({t['seconds_per_epoch']:.1f} s per epoch)")
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer runs; no long audio, writing or training")
    ap.add_argument("--no-long", action="store_true", help="skip the 3- and 10-minute clips")
    ap.add_argument("--no-train", action="store_true", help="skip writing and training throughput")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--train-sequences", type=int, default=48)
    ap.add_argument("--long-minutes", default="3,10", help="lengths of the streaming .npy clips")
    ap.add_argument("--usd-minutes", type=float, default=3.0, help="length of the in-memory .usdc clip")
    ap.add_argument("--out", type=Path, default=HERE / "RESULTS.md")
    args = ap.parse_args(argv)
    runs = 2 if args.quick else args.runs
    started = time.perf_counter()
    r: dict = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "busy": busy_processes()}
    r["machine"] = machine()
    log(f"machine: {r['machine']['cpu']}, {r['machine']['cores']} cores, load {r['machine']['load_average']}")
    with tempfile.TemporaryDirectory(prefix="facegen-bench-") as tmp:
        folder = Path(tmp)
        model, r["model"] = model_path(folder)
        log(f"model: {r['model']}")
        clips = {"5 s": make_clip(folder, 5.0, "clip5"), "60 s": make_clip(folder, 60.0, "clip60")}
        r["help"] = time_help(5)
        log(f"facegen --help: {r['help']['median']:.2f} s")
        r["imports"] = import_profile()
        r["animate"] = {}
        for name, (wav, txt, seconds) in clips.items():
            a = time_animate(wav, txt, model, folder / f"{wav.stem}.usdc", runs)
            a.update(audio_seconds=seconds, frames=round(seconds * FPS))
            r["animate"][name] = a
            log(f"animate {name}: {a['wall']:.2f} s wall, stages "
                + ", ".join(f"{k} {v:.2f}" for k, v in a["stages"].items()))
        r["forward"] = forward_times(model, clips, runs)
        if not (args.quick or args.no_long):
            r["long"] = {}
            for minutes in (float(m) for m in args.long_minutes.split(",")):
                clip = make_clip(folder, 60.0 * minutes, f"clip{minutes:g}m")
                x = time_long(folder, clip, model)
                x.update(audio_seconds=clip[2], path="streaming .npy (library)")
                r["long"][f"{minutes:g} min"] = x
                log(f"long {minutes:g} min: {x}")
            wav, txt, seconds = make_clip(folder, 60.0 * args.usd_minutes, "clip_usd")
            a = time_animate(wav, txt, model, folder / "clip_usd.usdc", 1)
            r["long"][f"{args.usd_minutes:g} min .usdc"] = {
                "audio_seconds": seconds, "frames": round(seconds * FPS), "wall": a["wall"],
                "rss_mb": a["rss_mb"],
                "output_mb": seconds * FPS * 23370 * 12 / 2**20, "path": "`facegen animate`, .usdc points",
                "stages": a["stages"]}
            log(f"{args.usd_minutes:g} min usdc: {a['wall']:.1f} s, {a['rss_mb']} MB")
        if not (args.quick or args.no_train):
            r["writing"] = writing_throughput(folder)
            r["train"] = training_speed(args.train_sequences)
    five, sixty = r["animate"]["5 s"], r["forward"]["60 s"]
    long10 = (r.get("long") or {}).get("10 min", {})
    r["targets"] = [
        ("model forward, 60 s clip (1500 frames)",
         f"{sixty['ours']:.3f} s = {sixty['seconds'] / sixty['ours']:.0f}x real time", "≥ 100x",
         sixty["seconds"] / sixty["ours"] >= TARGETS["forward_x_realtime"]),
        ("`facegen animate` 5 s clip, new process, .usdc", f"{five['wall']:.2f} s", "≤ 2.5 s",
         five["wall"] <= TARGETS["animate_5s_wall"]),
        ("`facegen --help`", f"{r['help']['median']:.2f} s", "≤ 0.5 s",
         r["help"]["median"] <= TARGETS["help_wall"]),
        ("no JIT warm-up on the animate path: librosa/numba never imported by `facegen animate`",
         "imported: " + (", ".join(five["modules"]) or "none of the heavy modules"), "no librosa, no numba",
         not {"librosa", "numba"} & set(five["modules"])),
    ]
    if "60 s" in r["animate"]:
        wall = r["animate"]["60 s"]["wall"]
        r["targets"].insert(2, ("`facegen animate` 60 s clip with its transcript, new process, .usdc",
                                f"{wall:.2f} s",
                                "≤ 6 s", wall <= TARGETS["animate_60s_wall"]))
    if long10 and "rss_mb" in long10:
        r["targets"].append(("10 min of audio to .npy, peak RSS", f"{long10['rss_mb']:.0f} MB", "≤ 2048 MB",
                             long10["rss_mb"] <= TARGETS["long_rss_mb"]))
    r["total_seconds"] = time.perf_counter() - started
    text = report(r)
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
