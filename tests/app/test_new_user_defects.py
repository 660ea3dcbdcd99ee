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


@pytest.mark.parametrize("delay", [0.05, 1.0, 2.5])
def test_ctrl_c_is_one_line_and_status_130(tmp_path, delay):
    """Seconds after main() is entered (the interpreter's start-up is not ours): at 0.05 s
    the parser is built, the scene read and numpy and pyopencl imported; later kernels build
    (a fresh compiler cache makes every build a real one, where an interrupt used to leave
    stray compiler lines)."""
    returncode, lines, err = _interrupted_render(tmp_path, "app.cli", delay)
    # 130, or killed by SIGINT (CPython re-raises the signal at exit when an interrupt hit code
    # run by an extension's PyRun_*, even though main() caught it): a shell reports 130 for both
    assert returncode in (130, -signal.SIGINT), err
    assert lines == ["lbwater: interrupted"], err
    assert not (tmp_path / "o.png").exists() and not list(tmp_path.glob("*.partial*"))


def _interrupted_render(tmp_path, module: str, delay: float) -> tuple[int, list, str]:
    """A 32x24 render of the pool through ``module``'s main, sent SIGINT ``delay`` s after the
    module is imported: (exit status, stderr lines but the first-build note, stderr)."""
    env = {**ENV, "POCL_CACHE_DIR": str(tmp_path / "kcache")}
    code = (f"import sys; from {module} import main; print('ready', file=sys.stderr, flush=True);"
            f" sys.exit(main(['render', 'scenes/pool.toml', '-o', {str(tmp_path / 'o.png')!r},"
            " '--width', '32', '--height', '24']))")
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stderr.readline() == "ready\n"
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if not ln.startswith("lbwater: building kernels")]
    return p.returncode, lines, err


@pytest.mark.parametrize("delay", [0.0, 0.005, 0.02, 0.05, 0.15, 0.4])
def test_ctrl_c_through_the_console_entry_is_one_line_from_its_first_statement(tmp_path, delay):
    """As the ``lbwater`` console script does (``from app.entry import main``): an interrupt
    right after app.entry is imported lands in the imports of app.cli, argparse, numpy and the
    command module, or in the parser, or later: always one line and status 130."""
    returncode, lines, err = _interrupted_render(tmp_path, "app.entry", delay)
    assert returncode in (130, -signal.SIGINT), err
    assert lines == ["lbwater: interrupted"], err
    assert not (tmp_path / "o.png").exists()


def test_an_interrupt_swallowed_by_a_callback_is_delivered_again(monkeypatch, capsys):
    """A Ctrl-C that lands in code whose exceptions Python only reports (importlib's module-lock
    weakref callback, a __del__) used to print 'Exception ignored ... KeyboardInterrupt' and
    let the command run on; main() delivers it again: one line and 130."""
    import types

    import app.cli as cli

    class Bomb:
        def __del__(self):
            raise KeyboardInterrupt   # as if the signal came while this ran

    def run(args):
        Bomb()                        # __del__ runs here, its exception "ignored"
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            time.sleep(0.001)         # the interrupt, delivered again, lands here
        return 0

    mod = types.ModuleType("fake_cmd")
    mod.add_arguments, mod.run = (lambda p: None), run
    monkeypatch.setitem(sys.modules, "fake_cmd", mod)
    monkeypatch.setattr(cli, "COMMANDS", [("fake", "fake_cmd", "a test command")])
    hook = sys.unraisablehook
    assert cli.main(["fake"]) == 130
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["lbwater: interrupted"], err
    assert sys.unraisablehook is hook                      # main() put the hook back


def test_console_script_and_module_run_install_the_handler_before_any_import():
    """``lbwater`` is app.entry:main, whose module imports only os, signal and sys before it
    installs the handler; ``python -m app.cli`` installs it before importing anything but sys."""
    import ast
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["lbwater"] == "app.entry:main"

    def head(path):   # module-level statements up to the first that is not an import
        body = ast.parse((ROOT / path).read_text()).body
        out = []
        for node in body:
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
                continue   # the docstring
            out.append(node)
        return out

    entry = head("app/entry.py")
    imports = [n for n in entry[:entry.index(next(n for n in entry if isinstance(
        n, ast.FunctionDef)))] if isinstance(n, ast.Import | ast.ImportFrom)]
    assert {a.name for n in imports for a in n.names} == {"os", "signal", "sys"}
    calls = [n for n in entry if isinstance(n, ast.Expr) and isinstance(n.value, ast.Call)]
    assert [c.value.func.id for c in calls] == ["install"]
    cli = head("app/cli.py")
    assert isinstance(cli[0], ast.ImportFrom) and cli[0].module == "__future__"
    assert isinstance(cli[1], ast.Import) and [a.name for a in cli[1].names] == ["sys"]
    guard = cli[2]
    assert isinstance(guard, ast.If) and "__main__" in ast.unparse(guard.test)
    assert "install()" in ast.unparse(guard)
    later = [n for n in cli[3:] if isinstance(n, ast.Import | ast.ImportFrom)]
    assert later == []   # argparse, importlib: inside the functions


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


def test_no_opencl_runtime_at_all_is_one_line(monkeypatch, capsys):
    """pyopencl (or its ICD loader) missing: one line, status 2."""
    import builtins

    real_import = builtins.__import__

    def no_pyopencl(name, *args, **kwargs):
        if name.split(".")[0] in ("pyopencl", "kernels"):
            raise ImportError("libOpenCL.so.1: cannot open shared object file", name="pyopencl")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pyopencl)
    assert main(["devices"]) == 2
    err = _one_line_error(capsys.readouterr().err, "devices")
    assert "pyopencl cannot be imported (libOpenCL.so.1" in err


def test_an_object_an_interrupt_left_half_built_says_nothing(monkeypatch, capsys):
    """An interrupt inside a constructor (pytools' compiler cache, cut short in its __init__)
    leaves an object whose __del__ fails as it goes: the command still ends with one line."""
    from app import cli

    class HalfBuilt:
        def __init__(self):
            raise KeyboardInterrupt

        def __del__(self):
            _ = self.mutex   # never set: AttributeError, which Python can only report

    def run(parser, argv):
        HalfBuilt()

    monkeypatch.setattr(cli, "_main", run)
    monkeypatch.setattr(sys, "unraisablehook", sys.__unraisablehook__)   # Python's: it prints
    hook = sys.unraisablehook
    assert cli.main(["devices"]) == 130
    assert capsys.readouterr().err.splitlines() == ["lbwater: interrupted"]
    assert sys.unraisablehook is hook   # put back for what runs next
