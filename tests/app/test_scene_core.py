"""Scene loading: the core sections, defaults, and one-line errors naming file, line, key, rule."""

import pytest

from app.errors import InputError
from app.scene import load_scene, parse_scene

GOOD = """
[scene]
name = "test pool"

[render]
width = 64
height = 48

[camera]
eye = [1, 2, 3]
fov = 45

[water]
size = [2.0, 1.0]
cells = [64, 32]
depth = 0.25
boundary = "noslip"

[water.rain]
rate = 10
seed = 7

[[water.drops]]
x = 1.0
y = 0.5
radius = 0.1
height = 0.02
"""


def parse(text, tmp_path):
    return parse_scene(text, tmp_path / "s.toml")


def test_good_scene_values_and_defaults(tmp_path):
    s = parse(GOOD, tmp_path)
    assert s.name == "test pool" and s.render.width == 64 and s.render.spp == 1
    assert s.camera.eye == (1.0, 2.0, 3.0) and s.camera.fov == 45.0
    w = s.water
    assert w.cells == (64, 32) and w.dx == pytest.approx(2.0 / 64) and w.boundary == "noslip"
    assert w.rain.rate == 10.0 and w.rain.seed == 7 and w.rain.radius > 0
    assert len(w.drops) == 1 and w.drops[0].height == 0.02


def test_no_water_section_is_allowed(tmp_path):
    assert parse("[render]\nwidth = 8\n", tmp_path).water is None


@pytest.mark.parametrize("edit, pattern", [
    (("depth = 0.25", "depth = -1"), r"s\.toml:\d+: \[water\] depth: depth = -1 is out of range"),
    (("depth = 0.25", "dpeth = 1"), r"unknown key 'dpeth'; valid keys: .*depth"),
    (('boundary = "noslip"', 'boundary = "sticky"'), r"'sticky' is not valid; allowed one of slip"),
    (("width = 64", 'width = "wide"'), r"\[render\] width: width = 'wide' should be an integer"),
    (("eye = [1, 2, 3]", "eye = [1, 2]"), r"eye = \[1, 2\] should be a list of 3 numbers"),
    (("cells = [64, 32]", "cells = [64, 64]"), r"non-square cells"),
    (("x = 1.0", "x = 9.0"), r"outside the pool"),
    (("[scene]", "[scenery]"), r"unknown section or key 'scenery'"),
    (("rate = 10", "rate = nan"), r"rate = nan is not finite"),
    (("width = 64", "width = 64\nwidth = 65"), r"not valid TOML"),
])
def test_bad_values_give_one_line_errors(tmp_path, edit, pattern):
    text = GOOD.replace(*edit)
    assert text != GOOD
    with pytest.raises(InputError, match=pattern) as info:
        parse(text, tmp_path)
    assert "\n" not in str(info.value)


def test_error_points_at_the_line(tmp_path):
    text = GOOD.replace("depth = 0.25", "depth = 0")
    line = next(i + 1 for i, t in enumerate(text.splitlines()) if t.startswith("depth"))
    with pytest.raises(InputError, match=rf"s\.toml:{line}:"):
        parse(text, tmp_path)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_scene(tmp_path / "nope.toml")
