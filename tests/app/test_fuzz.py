"""Fuzzed inputs, the short CI profile (bench/fuzz_inputs.py runs the long one): scene files
through the CLI, mesh files through the loader, and the Python API of the solver and the ray
query. The properties are in tests/app/fuzz_cases.py."""

import subprocess
import sys
from pathlib import Path

from hypothesis import HealthCheck, given, settings

from tests.app import fuzz_cases as fz


def CI(n: int) -> settings:
    """A fixed, fast profile: the same ``n`` examples every run."""
    return settings(max_examples=n, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much,
                                           HealthCheck.function_scoped_fixture])


@CI(300)
@given(content=fz.scene_texts(), extra=fz.RENDER_ARGS)
def test_scene_files_give_one_line_and_status_2(content, extra):
    with fz.workdir() as d:
        fz.check_scene_cli(content, [w for pair in extra for w in pair], d)


@CI(80)
@given(case=fz.mesh_files)
def test_mesh_files_load_or_give_one_line(case):
    with fz.workdir() as d:
        fz.check_mesh_file(*case, d)


@CI(40)
@given(case=fz.arrays_for_rays())
def test_intersect_inputs(case, rt):
    fz.check_intersect(*case, rt)


@CI(25)
@given(case=fz.solver_calls())
def test_solver_inputs(case, rt):
    fz.check_solver(*case, rt)


def test_missing_empty_and_folder_scene_files(tmp_path):
    """The cases a generator does not make: no file, a folder, an unreadable encoding."""
    for content in ("[render]\nwidth = 1e999\n", "[water]\ncells = [nan, 2]\n", b"\xff\xfe",
                    "[render]\n[render]\n"):
        assert fz.check_scene_cli(content, [], tmp_path) == "error"
    (tmp_path / "folder.toml").mkdir()
    for target in (tmp_path / "none.toml", tmp_path / "folder.toml"):
        r = subprocess.run([sys.executable, "-m", "app.cli", "render", str(target), "-o",
                            str(tmp_path / "o.png")], capture_output=True, text=True,
                           cwd=Path(__file__).resolve().parents[2], timeout=60)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and str(target) in r.stderr


def test_a_valid_scene_reaches_the_world(tmp_path):
    """The harness can tell a valid scene from an error (else every check would pass)."""
    text = "[render]\nwidth = 8\nheight = 6\n[[meshes]]\nfile = \"bunny_5k.obj\"\n"
    assert fz.check_scene_cli(text, [], tmp_path) == "valid"
