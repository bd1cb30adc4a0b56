"""The documentation tests hold for any valid robot a user adds to ``robots/``.

README "Adding a robot" and tutorial 1 tell the user to write ``robots/<name>.toml`` and generate
it; the pages must still run afterwards, including when the user followed the tutorials (which
create ``robots/my_arm.toml``, ``robots/two_link.toml``... themselves).
"""
from __future__ import annotations

import json
import shutil

import pytest

from . import runner
from .jsonschema_lite import validate
from .runner import DOCS, ROOT, Workspace, parse_blocks, robots_the_docs_create, run_doc, strict_json


def _validate_json(path, schema_name, where):
    schema = json.loads((DOCS / "schemas" / f"{schema_name}.schema.json").read_text())
    errs = validate(strict_json(path), schema)
    assert not errs, f"{where}: {path.name} does not match {schema_name}:\n" + "\n".join(errs[:20])


def test_the_tutorial_robots_are_known():
    # what tutorial 1 writes into robots/ (file blocks and -o robots/NAME.toml), and nothing shipped
    created = robots_the_docs_create()
    assert {"my_arm", "two_link"} <= created
    shipped = {p.stem for p in (ROOT / "robots").glob("*.toml")} & {"lwr4", "rx90", "scara", "tx40"}
    assert not created & shipped


@pytest.fixture
def checkout_with_user_robots(tmp_path, monkeypatch):
    """A copy of the checkout where the user added ``myarm`` (the README way: a robot file and its
    generated package) and followed tutorial 1 with different contents."""
    fake = tmp_path / "checkout"
    fake.mkdir()
    for name in ("symoro_gen", "docs"):
        (fake / name).symlink_to(ROOT / name)
    shutil.copy(ROOT / "README.md", fake / "README.md")
    shutil.copytree(ROOT / "robots", fake / "robots")
    shutil.copytree(ROOT / "generated", fake / "generated", ignore=shutil.ignore_patterns("__pycache__", ".*"))
    scara = (ROOT / "robots" / "scara.toml").read_text()
    (fake / "robots" / "myarm.toml").write_text(scara.replace('name = "scara"', 'name = "myarm"'))
    shutil.copytree(fake / "generated" / "scara", fake / "generated" / "myarm")
    # the tutorial's robots, as the user made them (here: other contents than the pages expect)
    for name in ("my_arm", "two_link"):
        (fake / "robots" / f"{name}.toml").write_text(scara.replace('name = "scara"', f'name = "{name}"'))
        (fake / "generated" / name).mkdir()
        (fake / "generated" / name / "manifest.json").write_text("{}")
    monkeypatch.setattr(runner, "ROOT", fake)
    return fake


def test_workspace_keeps_user_robots_and_drops_the_tutorials(checkout_with_user_robots, tmp_path):
    ws = Workspace(tmp_path / "ws")
    robots = {p.stem for p in (ws.cwd / "robots").glob("*.toml")}
    assert "myarm" in robots and {"lwr4", "rx90", "scara", "tx40"} <= robots
    assert not robots & {"my_arm", "two_link"}
    generated = {p.name for p in (ws.cwd / "generated").iterdir()}
    assert "myarm" in generated and not generated & {"my_arm", "two_link"}


@pytest.mark.parametrize("page", ["command-line.md", "tutorial-model.md"])
def test_pages_run_with_a_user_robot(checkout_with_user_robots, tmp_path, page):
    # the pages that list robots/ or write into it
    assert any("robots/" in b.text for b in parse_blocks(DOCS / page))
    log = run_doc(DOCS / page, Workspace(tmp_path / "ws"), validate_json=_validate_json)
    assert log.ran
