"""A config drives exactly the devices it names: one that mixes a simulated and a real device
(`[drive] url = "tcp://..."` with `[interferometer] port = "sim"`, or the reverse) is refused,
naming both keys, by every command that drives the rig and by the terminal UI, before anything
connects; never a silent fallback on the simulator (issue 22, item 2)."""

from __future__ import annotations

import asyncio

import pytest

from station.cli import main
from station.services.config import load_config
from station.tui.app import StationApp

# an address nothing listens on: were the config not refused, connecting would fail differently
MIXES = {
    "real drive, simulated laser": '[drive]\nurl = "tcp://127.0.0.1:9"\n[interferometer]\nport = "sim"\n',
    "simulated drive, real laser": '[drive]\nurl = "sim"\n[interferometer]\nport = "/dev/ttyNOPE"\n',
}


def _config(tmp_path, text: str):
    path = tmp_path / "mixed.toml"
    path.write_text(f'[station]\nrecordings_dir = "{tmp_path / "runs"}"\n' + text)
    return path


def _commands(cfg, tmp_path):
    table = tmp_path / "table.csv"
    table.write_text("leg,position_mm,error_fwd_um,error_rev_um\n1,0,0,0\n1,1,0,0\n")
    return {
        "sweep": ["sweep", "--config", str(cfg), "--out", str(tmp_path / "s.h5")],
        "verify": ["verify", "--leg", "1", "--config", str(cfg), "--out", str(tmp_path / "v.h5")],
        "push": ["push", str(table), "--leg", "1", "--config", str(cfg), "--yes"],
        "rollback": ["rollback", "--leg", "1", "--config", str(cfg), "--yes"],
        "ui": ["ui", "--config", str(cfg)],
    }


@pytest.mark.parametrize("mix", list(MIXES))
@pytest.mark.parametrize("command", ["sweep", "verify", "push", "rollback", "ui"])
def test_every_command_that_drives_the_rig_refuses_a_mixed_config(tmp_path, capsys, mix, command):
    cfg = _config(tmp_path, MIXES[mix])
    argv = _commands(cfg, tmp_path)[command]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"station {command}: error: {cfg}: [drive] url = ")
    assert "[interferometer] port = " in err[0] and "mix a simulated and a real device" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no session, no runs/ folder, no audit log


def test_a_drive_only_config_is_not_a_mix_for_push(tmp_path):
    """`station push --config` drives only the drive: a file naming just `[drive] url` is whole."""
    cfg = load_config(_config(tmp_path, '[drive]\nurl = "tcp://127.0.0.1:9"\n'))
    cfg.require_devices(interferometer=False)  # accepted (the push would then try to connect)


@pytest.mark.parametrize("mix", list(MIXES))
def test_the_ui_refuses_a_mixed_config_and_connects_nothing(tmp_path, mix):
    """The UI's own wiring path (StationApp -> open_rig), as another front end would call it."""
    cfg = load_config(_config(tmp_path, MIXES[mix]))

    async def go():
        app = StationApp(cfg, time_scale=0.0)
        async with app.run_test(size=(120, 40)) as pilot:
            for _ in range(500):
                if app.rig_state != "connecting":
                    break
                await pilot.pause(0.01)
            assert app.rig is None and app.rig_state == "not connected"
            assert "[drive] url" in app.rig_error and "[interferometer] port" in app.rig_error
            assert "mix a simulated and a real device" in app.rig_error

    asyncio.run(go())
