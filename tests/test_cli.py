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


def _hidden_leftovers(folder: Path) -> list:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_generate_replaces_only_a_package_it_wrote(tmp_path, cli):
    """A user's folder or file at OUT/<name> is an error naming it; --force overrides."""
    cli("--quiet", "generate", "scara", "--out", tmp_path, rc=0)
    cli("--quiet", "generate", "scara", "--out", tmp_path, rc=0)  # its own package: replaced
    assert _hidden_leftovers(tmp_path) == []

    thesis = tmp_path / "user" / "scara"
    thesis.mkdir(parents=True)
    (thesis / "thesis.tex").write_text("years of work")
    err = cli("generate", "scara", "--out", tmp_path / "user", rc=2).err
    assert str(thesis) in err and "--force" in err
    assert (thesis / "thesis.tex").read_text() == "years of work" and not (thesis / "manifest.json").exists()

    afile = tmp_path / "file" / "scara"
    afile.parent.mkdir()
    afile.write_text("a file")
    assert str(afile) in cli("generate", "scara", "--out", afile.parent, rc=2).err and afile.read_text() == "a file"
    assert _hidden_leftovers(afile.parent) == []

    cli("--quiet", "generate", "scara", "--out", afile.parent, "--force", rc=0)
    assert (afile / "manifest.json").is_file() and _hidden_leftovers(afile.parent) == []


def test_generate_long_robot_name_is_a_one_line_error(tmp_path, cli):
    bad = tmp_path / "long.toml"
    bad.write_text((ROOT / "robots" / "scara.toml").read_text().replace('name = "scara"', f'name = "{"a" * 300}"'))
    err = cli("generate", bad, "--out", tmp_path / "out", rc=2).err
    assert "long.toml" in err and "field 'name'" in err and "300 characters" in err
    assert "casadi" not in err.lower() and "Traceback" not in err
    assert not (tmp_path / "out").exists()
