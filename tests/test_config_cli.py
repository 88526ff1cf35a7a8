"""Strict configuration: every class of bad input is one line naming the key and the file."""

from pathlib import Path

import pytest

from mpf_mavlink.cli.main import main

CFG = "configs/paper_lemniscate.yaml"

BAD_SETS = [
    ("guidance.K_p=-1", "guidance.K_p", "> 0"),
    ("guidance.K_R=0", "guidance.K_R", "> 0"),
    ("guidance.alpha_m=-2", "guidance.alpha_m", "> 0"),
    ("guidance.bogus=1", "guidance.bogus", "unknown key"),
    ("nonsense.key=1", "nonsense", "unknown key"),
    ("vehicle.airspeed_m_s=0", "vehicle.airspeed_m_s", "> 0"),
    ("vehicle.airspeed_m_s=-15", "vehicle.airspeed_m_s", "> 0"),
    ("path.size_m=0", "path.size_m", "> 0"),
    ("kinematic.dt_s=fast", "kinematic.dt_s", "number"),
    ("guidance.psi_turn=maybe", "guidance.psi_turn", "true or false"),
    ("path.type=zigzag", "path.type", "one of"),
    ("path.radius_m=3", "path.radius_m", "not used"),
    ("kinematic.initial_position_ned_m=[1,2]", "kinematic.initial_position_ned_m", "3 numbers"),
    ("checks.c2=0.7", "checks.c2", "(0, 0.5)"),
    # float() parses these, but a float-typed field needs a finite number
    ("target.turn_rate_rad_s=inf", "target.turn_rate_rad_s", "finite"),
    ("target.turn_rate_rad_s=-Infinity", "target.turn_rate_rad_s", "finite"),
    ("target.turn_rate_rad_s=nan", "target.turn_rate_rad_s", "finite"),
    ("target.turn_rate_rad_s=1e", "target.turn_rate_rad_s", "number"),
    (
        "kinematic.initial_position_ned_m=[1e-9,2,zz]",
        "kinematic.initial_position_ned_m[2]",
        "number",
    ),
    # an origin without its AMSL altitude would put the vehicle far below the path in NED
    ("mavlink.origin_lat_deg=47.4", "mavlink.origin_lon_deg", "required with origin_lat_deg"),
]


@pytest.mark.parametrize("override,key,words", BAD_SETS)
def test_bad_values_are_one_line_naming_key_and_file(override, key, words, capsys):
    rc = main(["check", CFG, "--set", override])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1
    assert CFG in err and key in err and words in err


# PyYAML implements YAML 1.1, whose float needs a dot and a signed exponent: it reads 1e-9, 1E5
# and +3 (as +3 an int) differently from Python. Each spelling here is one float() accepts, with
# the value float() gives it (exact: the same parse, no arithmetic).
FLOAT_SPELLINGS = [("1e-9", 1e-9), ("1E5", 1e5), (".5", 0.5), ("+3", 3.0), ("-2.5e-3", -2.5e-3)]


@pytest.mark.parametrize("text,value", FLOAT_SPELLINGS)
def test_every_python_float_spelling_is_a_number_in_set_and_yaml(tmp_path, text, value):
    from mpf_mavlink.config.schema import load_config

    cfg = load_config(CFG, [f"target.turn_rate_rad_s={text}"])
    assert cfg.target.turn_rate_rad_s == value and type(cfg.target.turn_rate_rad_s) is float
    f = _write(
        tmp_path, f"path: {{type: circle, radius_m: 50}}\ntarget: {{turn_rate_rad_s: {text}}}\n"
    )
    assert load_config(f).target.turn_rate_rad_s == value
    # inside a vector (each component is a float field) and through the CLI's check
    cfg = load_config(CFG, [f"kinematic.initial_position_ned_m=[{text}, 0, {text}]"])
    assert cfg.kinematic.initial_position_ned_m == (value, 0.0, value)
    assert main(["check", CFG, "--set", f"target.turn_rate_rad_s={text}"]) in (0, 1)


def test_a_number_spelled_as_a_string_is_still_refused_where_a_string_or_int_is_wanted(capsys):
    # only float-typed fields coerce: an integer field keeps refusing "1e3" (a float in Python)
    rc = main(["check", CFG, "--set", "sim.record_every=1e3"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "sim.record_every" in err and "integer" in err


def _write(tmp_path, text):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize(
    "text,words",
    [
        ("path: {type: line, start_m: [0, 0, 0], end_m: [0, 0, 0]}\n", "zero length"),
        ("path: {type: circle}\n", "path.radius_m: required"),
        ("path: [1, 2\n", "not valid YAML"),
        ("- just\n- a list\n", "top level must be a mapping"),
        ("guidance: 3\n", "guidance: must be a mapping"),
        ("path: {type: spline, waypoints_m: [[0, 0, 0]], closed: false}\n", "at least 2 waypoints"),
    ],
)
def test_bad_files(tmp_path, text, words, capsys):
    f = _write(tmp_path, text)
    rc = main(["check", f])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and f in err and words in err and len(err.splitlines()) == 1


def test_missing_file_and_bad_set_syntax(capsys):
    assert main(["check", "does/not/exist.yaml"]) == 2
    assert "cannot read" in capsys.readouterr().err
    assert main(["check", CFG, "--set", "novalue"]) == 2
    assert "dotted.key=value" in capsys.readouterr().err


def test_check_fails_a_start_on_the_ground_far_below_the_path(capsys):
    """configs/bridge_arduplane.yaml's path is 100 m up; starting on the ground (z = 0) is 100 m
    below it, beyond checks.max_start_below_m = 30: exit 3 with the reason; 25 m below passes."""
    bridge = "configs/bridge_arduplane.yaml"
    assert main(["check", bridge, "--set", "kinematic.initial_position_ned_m=[-250,0,0]"]) == 3
    c = capsys.readouterr()
    assert "[FAIL] start_altitude: the vehicle starts 100 m below the path's lowest point" in c.out
    assert "start_altitude" in c.err
    assert main(["check", bridge, "--set", "kinematic.initial_position_ned_m=[-250,0,-75]"]) == 0
    assert "[PASS] start_altitude: start 25.0 m below" in capsys.readouterr().out


def test_check_passes_on_the_paper_and_fails_on_a_real_bank_limit(capsys):
    assert main(["check", CFG]) == 0
    out = capsys.readouterr().out
    # assumption 1, start altitude, gain condition, feasibility, climb, airspeed hold
    assert out.count("[PASS]") == 6
    # 45 deg of bank cannot fly the paper's lemniscate at 15 m/s: exit 3, and why.
    assert main(["check", CFG, "--set", "vehicle.max_bank_rad=0.785"]) == 3
    captured = capsys.readouterr()
    assert "[FAIL] feasibility" in captured.out and "feasibility" in captured.err


@pytest.mark.parametrize(
    "path", sorted(p.name for p in (Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))
)
def test_every_shipped_config_passes_its_own_strict_validation(path):
    # a shipped example that the strict loader refuses is the first thing a user meets
    from mpf_mavlink.campaign.design import load_campaign
    from mpf_mavlink.config import load_config

    f = Path(__file__).resolve().parents[1] / "configs" / path
    cfg = (load_campaign if path.startswith("campaign_") else load_config)(f)
    assert cfg is not None


@pytest.mark.parametrize(
    "path",
    sorted(
        p.name
        for p in (Path(__file__).resolve().parents[1] / "configs").glob("*.yaml")
        if not p.name.startswith("campaign_")
    ),
)
def test_a_config_written_out_loads_back_to_the_same_config(path):
    # what a run directory keeps (sim: bridge/config.yaml) must be the configuration flown,
    # field for field: written as YAML and validated again, it is equal to the original
    import dataclasses

    import yaml

    from mpf_mavlink.config import load_config
    from mpf_mavlink.config.schema import config_from_dict, config_to_dict

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / path)
    back = config_from_dict(yaml.safe_load(yaml.safe_dump(config_to_dict(cfg))), "written")
    assert dataclasses.replace(back, source=cfg.source) == cfg


def test_run_keeps_the_simulators_sections_as_read_and_never_loads_their_schema(tmp_path):
    # the live bridge flies what the link says: `run` neither validates nor imports the sil
    # and aircraft sections (a typo there is the simulator's error, raised where one is built)
    import subprocess
    import sys

    from mpf_mavlink.config import load_config
    from mpf_mavlink.config.schema import config_to_dict
    from mpf_mavlink.errors import ConfigError

    src = Path(__file__).resolve().parents[1] / "configs" / "bridge_px4.yaml"
    bad = ["sil.bogus_key=1"]
    with pytest.raises(ConfigError, match="sil.bogus_key"):
        load_config(src, bad)
    cfg = load_config(src, bad, sim_sections=False)
    # written out as read, so the run directory keeps what the file said
    assert config_to_dict(cfg)["sil"]["bogus_key"] == 1
    with pytest.raises(ConfigError, match="sil.bogus_key"):
        _ = cfg.sil  # read on first use, validated like the file
    good = load_config(src, sim_sections=False)
    assert good.sil == load_config(src).sil
    code = (
        "import sys\nfrom mpf_mavlink.config import load_config\n"
        "import mpf_mavlink.bridge.live, mpf_mavlink.cli.run\n"
        f"load_config({str(src)!r}, sim_sections=False)\n"
        "print('mpf_mavlink.config.sil' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stderr


def test_a_flown_run_against_a_simulated_vehicle_never_reads_the_simulators_sections(tmp_path):
    # `run` flies what the link says: from the parser to the hand-back (the checks, the
    # envelope's wind limit) nothing may read the sil section, so its schema is never imported
    import socket
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    veh = subprocess.Popen(
        [sys.executable, "-m", "mpf_mavlink.cli", "vehicle", "configs/default.yaml", "--serve",
         f"udpin:127.0.0.1:{port}", "--duration", "60"],
        cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        assert veh.stdout is not None
        veh.stdout.readline()  # printed once the vehicle serves
        code = (
            "import sys\nfrom mpf_mavlink.cli.main import main\n"
            f"rc = main(['run', 'configs/default.yaml', '--connect', 'udpout:127.0.0.1:{port}',"
            f" '--duration', '3', '--no-plots', '-q', '--out', {str(tmp_path / 'run')!r}])\n"
            "print(rc, 'mpf_mavlink.config.sil' in sys.modules)"
        )
        p = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True,
                           text=True, timeout=180)  # fmt: skip
    finally:
        veh.terminate()
        veh.wait(10)
    rc, loaded = p.stdout.split()[-2:]
    # 6: flown to its end, too short to judge (3 s): the flight went through every phase
    assert (rc, loaded) == ("6", "False"), p.stdout[-2000:] + p.stderr[-2000:]
