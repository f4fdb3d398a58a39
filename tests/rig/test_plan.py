"""Campaign plans: expansion into stable shot ids, overrides, and validation messages."""

from __future__ import annotations

from pathlib import Path

import pytest

from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import PlanAnalysis, load_plan

REPO = Path(__file__).resolve().parents[2]

BASE = """
name = "t"
operator = "op"
[accelerometer]
model = "M"
serial = "S"
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plan.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_shipped_plans_load() -> None:
    example = load_plan(REPO / "config/campaigns/example.toml")
    assert [s.id for s in example.shots] == [
        "s001-r1", "s001-r2", "s001-r3", "s002-r1", "s002-r2", "s002-r3", "s003-r1", "s003-r2",
    ]
    assert example.shots[-1].projectile == 2 and example.shots[-1].analysis.max_order == 8
    assert example.shots[0].analysis.max_order == 12
    demo = load_plan(REPO / "config/campaigns/demo.toml")
    assert demo.authorise_firing is True and len(demo.shots) == 3


def test_expansion_defaults_and_overrides(tmp_path: Path) -> None:
    plan = load_plan(write(tmp_path, BASE + """
[defaults]
pressure_bar = 2
projectile = 3
[defaults.analysis]
max_order = 10
dcm_ratio = 8.0
[[shots]]
repeats = 2
[[shots]]
pressure_bar = 4.5
projectile = 1
[shots.analysis]
order = 4
"""))
    assert [(s.id, s.index, s.entry, s.repeat) for s in plan.shots] == [
        ("s001-r1", 0, 1, 1), ("s001-r2", 1, 1, 2), ("s002-r1", 2, 2, 1),
    ]
    assert plan.shots[0].pressure_bar == 2.0 and isinstance(plan.shots[0].pressure_bar, float)
    assert plan.shots[0].analysis == PlanAnalysis(max_order=10, dcm_ratio=8.0)
    assert (plan.shots[2].pressure_bar, plan.shots[2].projectile) == (4.5, 1)
    # The entry's override keeps the inherited defaults it does not name.
    assert plan.shots[2].analysis == PlanAnalysis(max_order=10, order=4, dcm_ratio=8.0)
    assert plan.shot("s002-r1") is plan.shots[2]
    assert plan.text.startswith("\nname")


def test_fingerprint_follows_what_is_fired(tmp_path: Path) -> None:
    a = load_plan(write(tmp_path, BASE + "[[shots]]\npressure_bar = 2.0\nprojectile = 3\n"))
    b = load_plan(write(tmp_path, "# comment\n" + BASE + "[[shots]]\npressure_bar = 2.0\nprojectile = 3\n"))
    c = load_plan(write(tmp_path, BASE + "[[shots]]\npressure_bar = 2.5\nprojectile = 3\n"))
    assert a.fingerprint == b.fingerprint != c.fingerprint


def test_wide_plans_keep_ids_sortable(tmp_path: Path) -> None:
    entries = "".join(f"[[shots]]\npressure_bar = {1 + i / 1000}\nprojectile = 3\n" for i in range(1000))
    plan = load_plan(write(tmp_path, BASE + entries))
    ids = [s.id for s in plan.shots]
    assert ids[0] == "s0001-r1" and ids[-1] == "s1000-r1" and ids == sorted(ids)


@pytest.mark.parametrize(
    ("tail", "key", "reason"),
    [
        ("[[shots]]\npressure_bar = -1.0\nprojectile = 3\n", "shots[1].pressure_bar", "must be > 0"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 3\n[[shots]]\npressure_bar = 0\nprojectile = 3\n",
         "shots[2].pressure_bar", "must be > 0"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 4\n", "shots[1].projectile", "must be 1..3"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 2.0\n", "shots[1].projectile", "must be an integer"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 3\nrepeats = 0\n", "shots[1].repeats", "must be 1..10000"),
        ("[[shots]]\npressure_bar = \"2\"\nprojectile = 3\n", "shots[1].pressure_bar",
         "must be a number, got a string"),
        ("[[shots]]\npressure_bar = true\nprojectile = 3\n", "shots[1].pressure_bar",
         "must be a number, got a boolean"),
        ("[[shots]]\npresure_bar = 1.0\nprojectile = 3\n", "shots[1].presure_bar", "unknown key"),
        ("[[shots]]\nprojectile = 3\n", "shots[1].pressure_bar", "missing"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 3\n[shots.analysis]\nmax_ordr = 3\n",
         "shots[1].analysis.max_ordr", "unknown key"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 3\n[shots.analysis]\ndcm_damping = 1.5\n",
         "shots[1].analysis.dcm_damping", "must be > 0 and <= 1"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 3\n[shots.analysis]\ndcm_ratio = 0.5\n",
         "shots[1].analysis.dcm_ratio", "must be >= 1"),
        ("[[shots]]\npressure_bar = 1.0\nprojectile = 3\n[shots.analysis]\norder = 9\nmax_order = 8\n",
         "shots[1].analysis.order", "exceeds max_order 8"),
        ("[defaults]\nprojectile = 0\n[[shots]]\npressure_bar = 1.0\n", "defaults.projectile", "must be 1..3"),
        ("[defaults]\nrepeats = 2\n[[shots]]\npressure_bar = 1.0\nprojectile = 3\n", "defaults.repeats",
         "unknown key"),
        ("[shots]\npressure_bar = 1.0\n", "shots", "one or more [[shots]] tables"),
        ("", "shots", "missing"),
    ],
)
def test_validation_names_file_key_and_reason(tmp_path: Path, tail: str, key: str, reason: str) -> None:
    path = write(tmp_path, BASE + tail)
    with pytest.raises(ConfigError) as info:
        load_plan(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key}: "), message
    assert reason in message


@pytest.mark.parametrize(
    ("text", "key", "reason"),
    [
        ('operator = "op"\n[accelerometer]\nmodel = "M"\nserial = "S"\n[[shots]]\npressure_bar = 1.0\nprojectile = 3\n',
         "name", "missing"),
        (BASE.replace('serial = "S"', 'serial = ""') + "[[shots]]\npressure_bar = 1.0\nprojectile = 3\n",
         "accelerometer.serial", "must not be empty"),
        (BASE.replace('model = "M"', 'model = "M"\ncolour = "red"') + "[[shots]]\npressure_bar = 1\nprojectile = 3\n",
         "accelerometer.colour", "unknown key"),
        ('extra = 1\n' + BASE + "[[shots]]\npressure_bar = 1\nprojectile = 3\n", "extra", "unknown key"),
        (BASE.replace('name = "t"', 'name = "a/b"') + "[[shots]]\npressure_bar = 1\nprojectile = 3\n",
         "name", "folder name"),
        ('authorise_firing = "yes"\n' + BASE + "[[shots]]\npressure_bar = 1\nprojectile = 3\n",
         "authorise_firing", "true or false"),
    ],
)
def test_top_level_validation(tmp_path: Path, text: str, key: str, reason: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_plan(path)
    assert str(info.value).startswith(f"{path}: {key}: ") and reason in str(info.value)


def test_bad_toml_and_missing_file(tmp_path: Path) -> None:
    path = write(tmp_path, BASE + "[[shots]\n")
    with pytest.raises(ConfigError, match=r"plan\.toml: not valid TOML: .*line"):
        load_plan(path)
    with pytest.raises(ConfigError, match="no such plan file"):
        load_plan(tmp_path / "absent.toml")


def test_a_device_a_folder_or_a_binary_file_is_not_a_plan(tmp_path: Path) -> None:
    """/dev/zero was read to the end (a MemoryError traceback); now one line, nothing read."""
    with pytest.raises(ConfigError, match=r"^/dev/zero: not a regular file .*not a plan file$"):
        load_plan("/dev/zero")
    with pytest.raises(ConfigError, match=rf"^{tmp_path}: is a folder, not a plan file$"):
        load_plan(tmp_path)
    binary = tmp_path / "plan.toml"
    binary.write_bytes(b"name = 1\n\xff\xfe")
    with pytest.raises(ConfigError, match=r"plan\.toml: not UTF-8 text \(byte 9\): is it a binary file\?$"):
        load_plan(binary)


def test_dcm_ratio_auto_is_the_default_and_can_be_written(tmp_path):
    from hopkinson.rig.plan import load_plan

    path = tmp_path / "auto.toml"
    path.write_text('name = "a"\noperator = "op"\n[accelerometer]\nmodel = "m"\nserial = "1"\n'
                    '[[shots]]\npressure_bar = 1.0\nprojectile = 3\n'
                    '[[shots]]\npressure_bar = 1.0\nprojectile = 3\n[shots.analysis]\ndcm_ratio = "auto"\n'
                    '[[shots]]\npressure_bar = 1.0\nprojectile = 3\n[shots.analysis]\ndcm_ratio = 12.5\n')
    plan = load_plan(path)
    assert [s.analysis.dcm_ratio for s in plan.shots] == [None, None, 12.5]


def test_a_second_accelerometer_is_named_in_the_plan_and_checked_against_the_rigs_channels(tmp_path: Path) -> None:
    import dataclasses

    from hopkinson.rig.campaign_setup import check_plan
    from hopkinson.rig.config import load_rig_config

    shots = "[[shots]]\npressure_bar = 2.0\nprojectile = 3\n"
    plan = load_plan(write(tmp_path, BASE + '[accelerometer_2]\nmodel = "AYZ-3"\nserial = "SN0002"\n' + shots))
    assert plan.sensor_identities() == {"response_2": {"model": "AYZ-3", "serial": "SN0002"}}
    assert load_plan(write(tmp_path, BASE + shots)).sensor_identities() == {}
    with pytest.raises(ConfigError, match=r"accelerometer_2\.serial: missing"):
        load_plan(write(tmp_path, BASE + '[accelerometer_2]\nmodel = "AYZ-3"\n' + shots))
    with pytest.raises(ConfigError, match=r"accelerometer_2.*sensitivity"):
        load_plan(write(tmp_path, BASE + '[accelerometer_2]\nmodel = "A"\nserial = "B"\nsensitivity = 1\n' + shots))
    config = load_rig_config(REPO / "config" / "rig-sim.toml")
    assert "response_2" not in config.digitizer.channels
    with pytest.raises(ConfigError, match=r"response_2: an accelerometer is named for it, but the rig records no "
                                          r"response_2 channel"):
        check_plan(plan, config)  # before anything is created or fired
    digitizer = dataclasses.replace(config.digitizer, channels={**config.digitizer.channels, "response_2": "CH4"},
                                    ranges_v={**config.digitizer.ranges_v, "response_2": 10.0})
    check_plan(plan, dataclasses.replace(config, digitizer=digitizer))
