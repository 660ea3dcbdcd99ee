"""The defects a new user hit (issue 14's first list), each held by a test: device aliases,
Ctrl-C, outputs checked before any work, quiet mesh errors, help texts, benchmark output."""

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from app.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "POCL_AFFINITY": "0"}

SCENE = """
[render]
width = 8
height = 6
[camera]
eye = [0.0, 0.3, 0.6]
target = [0.0, 0.1, 0.0]
[[meshes]]
file = "bunny_5k.obj"
size = 0.3
"""


def _cli(*args, timeout=120, env=None):
    return subprocess.run([sys.executable, "-m", "app.cli", *args], capture_output=True,
                          text=True, timeout=timeout, env=env or ENV, cwd=ROOT)


def _one_line_error(err: str, command: str) -> str:
    err = err.strip()
    assert err.startswith(f"lbwater {command}: error: ") and "\n" not in err, err
    assert "Traceback" not in err
    return err


# ---- --device pocl --------------------------------------------------------------------------
def test_device_pocl_as_the_readme_says(capsys):
    assert main(["devices", "--device", "pocl", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    chosen = [r for r in rows if r["selected"]]
    assert len(chosen) == 1 and chosen[0]["platform"] == "Portable Computing Language"
    assert chosen[0]["device_fence"]


# ---- the parser imports nothing heavy; help lists every command; Ctrl-C is one line --------
def test_parser_imports_no_opencl_and_help_lists_frame():
    code = ("import sys; from app.cli import build_parser\n"
            "for argv in (['--help'], ['render', 's'], ['bench', 'lbm'], ['devices']):\n"
            "    build_parser(argv)\n"
            "print(sorted(m for m in ('pyopencl', 'pyvista', 'vtk', 'matplotlib')"
            " if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=ENV, cwd=ROOT, timeout=60)
    assert out.stdout.strip() == "[]", out.stderr
    top = _cli("--help", timeout=60).stdout
    assert all(name in top for name, _, _ in COMMANDS)
    bench = _cli("bench", "--help", timeout=60).stdout
    assert all(name in bench for name in ("lbm", "bvh", "render", "frame"))


def test_help_texts_name_only_files_in_the_repository():
    import importlib

    from app.bench import BENCHES

    texts = []
    for _, module, help_text in COMMANDS + BENCHES:
        mod = importlib.import_module(module)
        texts += [help_text, mod.__doc__ or ""]
    text = "\n".join(texts)
    assert "../" not in text and "shared/" not in text
    for name in set(re.findall(r"[\w./-]+\.(?:md|py|sh|toml)\b", text)):
        if name.startswith(("out.", "pool.", "x.")) or "/" not in name and name.endswith(".py"):
            continue
        assert (ROOT / name).exists() or (ROOT / "scenes" / name).exists() \
            or (ROOT / "docs" / name).exists(), f"help names {name}, not in the repository"


@pytest.mark.parametrize("delay", [0.4, 1.5, 3.0])
def test_ctrl_c_is_one_line_and_status_130(tmp_path, delay):
    """At 0.4 s the scene is being read; later the scene loads and kernels build (a fresh
    compiler cache makes every build a real one, where an interrupt used to leave stray
    compiler lines)."""
    env = {**ENV, "POCL_CACHE_DIR": str(tmp_path / "kcache")}
    p = subprocess.Popen([sys.executable, "-m", "app.cli", "render", "scenes/pool.toml",
                          "-o", str(tmp_path / "o.png"), "--width", "32", "--height", "24"],
                         cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if not ln.startswith("lbwater: building kernels")]
    # 130, or killed by SIGINT (CPython re-raises the signal at exit when an interrupt hit code
    # run by an extension's PyRun_*, even though main() caught it): a shell reports 130 for both
    assert p.returncode in (130, -signal.SIGINT), err
    assert lines == ["lbwater: interrupted"], err
    assert not (tmp_path / "o.png").exists() and not list(tmp_path.glob("*.partial*"))


def test_interrupt_during_a_build_waits_for_the_compiler(rt):
    from kernels.runtime import _build_guard

    reached = False
    with pytest.raises(KeyboardInterrupt), _build_guard(rt.device):
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
        time.sleep(0.05)
        reached = True   # the compiler would have finished undisturbed
    assert reached


def test_slow_build_prints_one_note_with_the_cache(rt, monkeypatch, capsys):
    import kernels.runtime as runtime_mod

    monkeypatch.setattr(runtime_mod, "BUILD_NOTE_AFTER_S", 0.02)
    monkeypatch.setattr(runtime_mod, "_build_note_shown", False)
    for _ in range(2):
        with runtime_mod._build_guard(rt.device):
            time.sleep(0.2)
    err = capsys.readouterr().err
    assert err.count("building kernels (first run only; cache: ") == 1
    assert runtime_mod.driver_cache_dir(rt.device) in err
    monkeypatch.setattr(runtime_mod, "_build_note_shown", False)
    with runtime_mod._build_guard(rt.device):
        pass   # a cached build: no note
    assert capsys.readouterr().err == ""


# ---- outputs checked before any work, errors naming the user's path -----------------------
@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(SCENE)
    return path


def test_output_under_a_file_says_not_a_directory(tmp_path, scene, capsys):
    (tmp_path / "somefile").write_text("x")
    t0 = time.perf_counter()
    assert main(["render", str(scene), "-o", str(tmp_path / "somefile" / "out.png")]) == 2
    err = _one_line_error(capsys.readouterr().err, "render")
    assert f"{tmp_path / 'somefile'} is not a directory" in err and "out.png" in err
    assert time.perf_counter() - t0 < 5   # before any work


def test_unwritable_aov_writes_nothing(tmp_path, scene, capsys):
    (tmp_path / "somefile").write_text("x")
    out = tmp_path / "o.png"
    assert main(["render", str(scene), "-o", str(out),
                 "--aov", str(tmp_path / "somefile" / "a.npz")]) == 2
    err = _one_line_error(capsys.readouterr().err, "render")
    assert "--aov" in err and "somefile" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml", "somefile"]


@pytest.mark.skipif(not Path("/sys").is_dir() or os.access("/sys", os.W_OK)
                    and os.geteuid() != 0, reason="needs Linux's read-only /sys")
def test_unwritable_folder_names_the_users_path_not_a_temp_file(scene, capsys):
    assert main(["render", str(scene), "-o", "/sys/out.png"]) == 2
    err = _one_line_error(capsys.readouterr().err, "render")
    assert "'/sys/out.png'" in err and ".partial" not in err


def test_atomic_path_errors_name_the_target(tmp_path):
    from app.errors import InputError
    from app.io import atomic_path

    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=re.escape(str(tmp_path / "f" / "o.png"))), \
            atomic_path(tmp_path / "f" / "o.png"):
        pass


def test_simulate_rejects_a_save_that_is_not_npz(tmp_path, capsys):
    save = tmp_path / "s.txt"
    assert main(["simulate", "scenes/pool.toml", "--save", str(save), "--steps", "1"]) == 2
    err = _one_line_error(capsys.readouterr().err, "simulate")
    assert "--save" in err and "must end in .npz" in err and not save.exists()


def test_bench_out_that_is_a_file_fails_first(tmp_path, capsys):
    (tmp_path / "f").write_text("x")
    assert main(["bench", "lbm", "--out", str(tmp_path / "f")]) == 2
    assert "is a file, not a folder" in _one_line_error(capsys.readouterr().err, "bench")


# ---- a malformed mesh: one line, no VTK log -----------------------------------------------
def test_malformed_obj_is_one_line_without_vtk_noise(tmp_path, capfd):
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 0\nv x y z\nf 1 2 3\ngarbage\n")
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.replace("bunny_5k.obj", "bad.obj"))
    assert main(["render", str(scene), "-o", str(tmp_path / "o.png")]) == 2
    cap = capfd.readouterr()
    err = _one_line_error(cap.err, "render")
    assert "bad.obj" in err and "L.3" in err, err
    assert cap.out == ""


# ---- benchmark output ------------------------------------------------------------------
def test_bench_lbm_prints_no_none_and_writes_rows(tmp_path, capsys):
    assert main(["bench", "lbm", "--sizes", "16", "--steps", "2", "--repeats", "1",
                 "--variants", "flat", "--bandwidth-mib", "1", "--out", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert "None" not in err and "check flat work-group auto" in err
    rows = json.loads((tmp_path / "lbm.json").read_text())["rows"]
    assert [r["n"] for r in rows] == [16] and (tmp_path / "lbm.csv").is_file()


def test_bench_lbm_defaults_suit_the_device():
    from argparse import Namespace

    from app.bench_lbm import CPU_DEFAULTS, GPU_DEFAULTS, apply_device_defaults

    cpu = Namespace(sizes=None, steps=None, repeats=None, bandwidth_mib=None)
    apply_device_defaults(cpu, is_gpu=False)
    assert max(cpu.sizes) <= 256 and cpu.sizes == CPU_DEFAULTS["sizes"]
    gpu = Namespace(sizes=[32], steps=None, repeats=None, bandwidth_mib=None)
    apply_device_defaults(gpu, is_gpu=True)
    assert gpu.sizes == [32] and gpu.steps == GPU_DEFAULTS["steps"]


def test_bench_render_summary_is_readable():
    from app.bench_render import summary_line

    row = {"scene": "hand", "size": 300, "wall_ms": 12.5, "fps": 80.0, "kernel_total_ms": 11.0,
           "secondary_rays": 0, "seed_ms": None, "speedup_fps": None, "local_size": 64,
           "fuse_trace_shade": False,
           "stages_ms": {"render.trace": 5.0, "render.raygen": 0.1, "render.shade": 2.0}}
    line = summary_line(row)
    assert "None" not in line and "{" not in line and "no seed number" in line
    assert "trace 5.000" in line.split("slowest")[1]
    line = summary_line(row | {"size": 512, "seed_ms": 11.6, "speedup_fps": 0.9})
    assert "seed 11.6 ms, 0.9x" in line
