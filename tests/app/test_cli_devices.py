"""`lbwater devices` and the CLI's error contract."""

import json

from app.cli import main


def test_devices_json(capsys):
    assert main(["devices", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows and sum(r["selected"] for r in rows) == 1
    assert {"name", "type", "compute_units", "global_mem_mib", "opencl_version",
            "extensions"} <= set(rows[0])


def test_devices_table(capsys):
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "compute units" in out and "*" in out


def test_bad_device_is_one_line_and_exit_2(capsys):
    assert main(["devices", "--device", "warp-drive"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "warp-drive" in err and err.startswith("lbwater devices: error")
