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


def _hidden_leftovers(folder: Path) -> list:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_generate_replaces_only_a_package_it_wrote(tmp_path, capsys):
    """Issue 15: a user's folder or file at OUT/<name> is an error naming it; --force overrides."""
    assert main(["--quiet", "generate", "scara", "--out", str(tmp_path)]) == 0
    assert main(["--quiet", "generate", "scara", "--out", str(tmp_path)]) == 0  # its own package: replaced
    assert _hidden_leftovers(tmp_path) == []

    thesis = tmp_path / "user" / "scara"
    thesis.mkdir(parents=True)
    (thesis / "thesis.tex").write_text("years of work")
    assert main(["generate", "scara", "--out", str(tmp_path / "user")]) == 2
    err = capsys.readouterr().err
    assert str(thesis) in err and "--force" in err
    assert (thesis / "thesis.tex").read_text() == "years of work" and not (thesis / "manifest.json").exists()

    afile = tmp_path / "file" / "scara"
    afile.parent.mkdir()
    afile.write_text("a file")
    assert main(["generate", "scara", "--out", str(afile.parent)]) == 2
    assert str(afile) in capsys.readouterr().err and afile.read_text() == "a file"
    assert _hidden_leftovers(afile.parent) == []

    assert main(["--quiet", "generate", "scara", "--out", str(afile.parent), "--force"]) == 0
    assert (afile / "manifest.json").is_file() and _hidden_leftovers(afile.parent) == []


def test_generate_long_robot_name_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "long.toml"
    bad.write_text((ROOT / "robots" / "scara.toml").read_text().replace('name = "scara"', f'name = "{"a" * 300}"'))
    assert main(["generate", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "long.toml" in err and "field 'name'" in err and "300 characters" in err
    assert "casadi" not in err.lower() and "Traceback" not in err
    assert not (tmp_path / "out").exists()
