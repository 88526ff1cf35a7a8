"""Every CLI path: one line naming the culprit, exit 2, nothing left behind (issue 26), the exit
codes in each command's --help, and compare's verdict column."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpf_mavlink.cli.main import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
DEMO = str(ROOT / "configs" / "default.yaml")
CIRCLE = str(ROOT / "configs" / "compare" / "static_circle.yaml")
COMMANDS = ("check", "sim", "plot", "run", "replay", "vehicle", "campaign", "compare")


def _one_line_error(capsys: pytest.CaptureFixture[str], culprit: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert culprit in err, err
    return err


@pytest.mark.parametrize("command", COMMANDS)
def test_help_lists_the_exit_codes(command, capsys):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([command, "--help"])
    assert e.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "exit codes: 0" in out
    if command in ("sim", "run"):  # the flight's verdict: FAIL 5, NOT JUDGED 6
        assert "5 verdict FAIL" in out and "6 verdict NOT JUDGED" in out


def test_vehicle_refuses_an_unresolvable_host_and_a_zero_duration(capsys):
    rc = main(["vehicle", DEMO, "--serve", "udpout:nosuchhost.invalid:14550", "--duration", "5"])
    assert rc == 2
    _one_line_error(capsys, "cannot resolve host 'nosuchhost.invalid'")
    for d in ("0", "-5"):
        with pytest.raises(SystemExit) as e:
            main(["vehicle", DEMO, "--serve", "udpin:127.0.0.1:0", "--duration", d])
        assert e.value.code == 2
        _one_line_error(capsys, "--duration: must be > 0")


def test_a_failed_run_leaves_no_run_directory(tmp_path, capsys):
    out = tmp_path / "a" / "run"
    cfg = str(ROOT / "configs" / "bridge_px4.yaml")
    rc = main(["run", cfg, "--connect", "tcp:nosuchhost.invalid:5760", "--out", str(out)])
    assert rc == 2
    _one_line_error(capsys, "--connect tcp:nosuchhost.invalid:5760: cannot resolve host")
    assert not out.exists()
    # nobody answers: the bridge made the directory and wrote the tlog of its own heartbeats
    rc = main(["run", cfg, "--connect", "udpout:127.0.0.1:9", "--heartbeat-timeout", "0.5",
               "--out", str(out), "-q"])  # fmt: skip
    assert rc == 2
    _one_line_error(capsys, "no HEARTBEAT")
    assert not out.exists() and not out.parent.exists() and tmp_path.exists()


def test_campaign_with_no_scheduler_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "c"
    rc = main(["campaign", str(ROOT / "configs" / "campaign_roa.yaml"), "--out", str(out),
               "--scheduler", "tcp://127.0.0.1:1", "-q"])  # fmt: skip
    assert rc == 2
    _one_line_error(capsys, "--scheduler tcp://127.0.0.1:1: no dask scheduler answered")
    assert not out.exists()
    rc = main(["campaign", str(ROOT / "configs" / "campaign_roa.yaml"), "--out", str(out),
               "--scheduler", "127.0.0.1:1", "-q"])  # fmt: skip
    assert rc == 2
    _one_line_error(capsys, "not a dask scheduler address")


def test_sil_flavour_is_one_key(capsys):
    # mavlink.flavour and hold_mode follow sil.flavour unless set; set, they must agree
    assert main(["check", DEMO, "--set", "sil.flavour=ardupilot"]) == 0
    capsys.readouterr()
    rc = main(
        ["check", DEMO, "--set", "sil.flavour=ardupilot", "--set", "mavlink.hold_mode=AUTO.LOITER"]
    )
    assert rc == 2
    _one_line_error(capsys, "mavlink.hold_mode: 'AUTO.LOITER' is not an ArduPlane mode")


def test_compare_reports_the_verdict_and_exits_0_when_every_flight_ran(tmp_path, capsys):
    # 30 s of the kinematic plant with the steady window from 120 s: no figure, NOT JUDGED, but
    # every flight ran: exit 0, "n/a" in the table, never "None"
    rc = main(["compare", CIRCLE, "--laws", "mpf,pursuit", "--duration", "30",
               "--out", str(tmp_path / "c"), "-q", "--no-plots"])  # fmt: skip
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert "None" not in cap.out + cap.err
    table = [ln for ln in cap.out.splitlines() if ln.startswith("| mpf ")]
    assert table and "| NOT JUDGED |" in table[0] and "n/a" in table[0]
    rows = json.loads((tmp_path / "c" / "compare.json").read_text())["rows"]
    assert rows["pursuit"]["verdict"] == "NOT JUDGED"
    # a zero duration is bad input: one line, exit 2
    with pytest.raises(SystemExit) as e:
        main(["compare", CIRCLE, "--duration", "0", "--out", str(tmp_path / "d")])
    assert e.value.code == 2
    _one_line_error(capsys, "--duration: must be > 0")
    assert not (tmp_path / "d").exists()
