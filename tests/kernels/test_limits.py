"""Requests that do not fit the device fail before allocating, with the estimate and the limit:
the LBM grid (32-bit indices, memory) and the renderer's image."""

from types import SimpleNamespace

import pytest

from kernels.limits import MEMORY_FRACTION, DeviceLimitError, check_fits


def _fake_rt(total_mib: int, max_alloc_mib: int):
    dev = SimpleNamespace(name="Fake GPU ", global_mem_size=total_mib << 20,
                          max_mem_alloc_size=max_alloc_mib << 20)
    return SimpleNamespace(device=dev)


def test_check_fits_names_estimate_and_limit():
    rt = _fake_rt(1024, 256)
    check_fits(rt, int(MEMORY_FRACTION * (1024 << 20)), "a", largest=256 << 20)  # just fits
    with pytest.raises(DeviceLimitError, match=r"b needs a 257 MiB buffer; Fake GPU allows "
                                               r"at most 256 MiB per buffer"):
        check_fits(rt, 1, "b", largest=257 << 20)
    with pytest.raises(DeviceLimitError, match=r"c needs about 1,000 MiB of device memory; "
                                               r"Fake GPU has 1,024 MiB"):
        check_fits(rt, 1000 << 20, "c")


def test_lbm_refuses_32_bit_index_overflow_before_allocating(rt):
    import lbm
    from lbm.limits import MAX_CELLS, check_grid

    assert 9 * MAX_CELLS < 2**31 <= 9 * (MAX_CELLS + 1)
    big = _fake_rt(1 << 30, 1 << 30)  # a device with 1 PiB: only the index limit is left
    check_grid(big, 15446, 15446)
    with pytest.raises(ValueError, match=r"15447x15447 has 238,609,809 cells; the LBM kernels "
                                         r"address at most 238,609,294"):
        check_grid(big, 15447, 15447)
    with pytest.raises(ValueError, match="32-bit population index"):
        lbm.ShallowWater(16000, 16000, 0.01, device=rt)


def test_lbm_grid_larger_than_the_device_fails_with_the_estimate(rt):
    import lbm
    from lbm.limits import MAX_CELLS

    max_alloc = rt.device.max_mem_alloc_size
    side = int((max_alloc / 36) ** 0.5) + 64   # one population buffer over the limit
    if side * side > MAX_CELLS:  # a big GPU: the 32-bit population index is the first limit
        with pytest.raises(ValueError, match=rf"grid {side}x{side} has .* cells; the LBM "
                                             r"kernels address at most"):
            lbm.ShallowWater(side, side, 0.01, device=rt)
        return
    with pytest.raises(DeviceLimitError, match=rf"LBM grid {side}x{side} needs a .* buffer; "
                                               r".* allows at most"):
        lbm.ShallowWater(side, side, 0.01, device=rt)


def test_render_too_large_for_the_device_is_one_line(rt, tmp_path, capsys):
    from app.cli import main

    side = int((rt.device.max_mem_alloc_size / 16) ** 0.5) + 64   # framebuffer over the limit
    if side > 16384:
        pytest.skip(f"the CLI's 16384 px limit fits this device ({side} px would not)")
    scene = tmp_path / "s.toml"
    scene.write_text('[[meshes]]\nfile = "mirror_box.obj"\n')
    out = tmp_path / "o.png"
    assert main(["render", str(scene), "-o", str(out), "--width", str(side),
                 "--height", str(side)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"render {side}x{side} needs a" in err and "allows at most" in err and "\n" not in err
    assert not out.exists()
