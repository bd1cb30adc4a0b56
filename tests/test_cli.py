"""Command-line behaviour: exit status 2 and nothing written on bad input."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_generate_writes_package(tmp_path, cli):
    cli("--quiet", "generate", "scara", "--out", tmp_path, rc=0)
    assert (tmp_path / "scara" / "__init__.py").exists()


def test_generate_bad_robot_file_exits_2_and_writes_nothing(tmp_path, cli):
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "robots" / "scara.toml").read_text().replace("sigma = 1", "sigma = 7"))
    out = tmp_path / "out"
    err = cli("generate", bad, "--out", out, rc=2).err
    assert "bad.toml" in err and "frame 3" in err and "sigma" in err
    assert not out.exists()


def test_unknown_robot_lists_known_ones(cli):
    assert "lwr4" in cli("generate", "no_such_robot", rc=2).err
