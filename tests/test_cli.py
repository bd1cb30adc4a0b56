"""Command-line behaviour: exit status 2 and nothing written on bad input."""
from pathlib import Path

from symoro_gen.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_generate_writes_package(tmp_path, capsys):
    assert main(["--quiet", "generate", "scara", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "scara" / "__init__.py").exists()


def test_generate_bad_robot_file_exits_2_and_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "robots" / "scara.toml").read_text().replace("sigma = 1", "sigma = 7"))
    out = tmp_path / "out"
    assert main(["generate", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "frame 3" in err and "sigma" in err
    assert not out.exists()


def test_unknown_robot_lists_known_ones(capsys):
    assert main(["generate", "no_such_robot"]) == 2
    assert "lwr4" in capsys.readouterr().err
