"""Fuzz: URDF (``import-urdf FILE -o OUT.toml``) and SYMORO ``.par`` files (``import-par FILE -o
OUT.toml``): attribute values and list elements replaced by NaN/inf/huge/negative/garbage, lines
dropped or duplicated, truncation, binary garbage."""
from __future__ import annotations

import re

from hypothesis import given
from hypothesis import strategies as st

from symoro_gen.description import load_robot
from symoro_gen.description.par import export_par

from .helpers import FUZZ, run_case

URDF = """<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"/>
  <link name="upper">
    <inertial>
      <origin xyz="0.2 0 0" rpy="0 0 0"/>
      <mass value="3.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/>
    </inertial>
  </link>
  <link name="fore">
    <inertial>
      <origin xyz="0.15 0 0.01" rpy="0 0 0"/>
      <mass value="1.5"/>
      <inertia ixx="0.004" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/>
    </inertial>
  </link>
  <link name="tool">
    <inertial>
      <mass value="0.2"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>
    </inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/>
    <child link="upper"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="50" velocity="3"/>
    <dynamics damping="0.5" friction="0.1"/>
  </joint>
  <joint name="elbow" type="prismatic">
    <parent link="upper"/>
    <child link="fore"/>
    <origin xyz="0.4 0 0" rpy="0 0 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="30" velocity="3"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="fore"/>
    <child link="tool"/>
    <origin xyz="0.3 0 0" rpy="0 0 0"/>
  </joint>
</robot>
"""
ODD = ["nan", "inf", "-inf", "-1", "0", "1e308", "-1e308", "abc", "", "1 2", "0x10", "1,5", "1e-320", "\u00e9"]
_ATTR = re.compile(r'(\w+)="([^"]*)"')


def _damaged(draw, text: str) -> bytes:
    lines = text.splitlines(keepends=True)
    i = draw(st.integers(0, len(lines) - 1))
    kind = draw(st.sampled_from(["drop", "duplicate", "truncate", "garbage"]))
    if kind == "drop":
        return "".join(lines[:i] + lines[i + 1:]).encode()
    if kind == "duplicate":
        return "".join(lines[: i + 1] + lines[i:]).encode()
    raw = text.encode()
    cut = draw(st.integers(0, len(raw)))
    if kind == "truncate":
        return raw[:cut]
    return raw[:cut] + draw(st.binary(min_size=1, max_size=30)) + raw[cut + draw(st.integers(0, 30)):]


@st.composite
def urdf_attribute_edit(draw):
    m = draw(st.sampled_from(list(_ATTR.finditer(URDF))))
    new = draw(st.sampled_from(ODD + ["1 2 3", "nan 0 0", "0 0 1e308", "revolute", "continuous", "floating"]))
    return (URDF[: m.start(2)] + new + URDF[m.end(2):]).encode()


@st.composite
def urdf_damage(draw):
    return _damaged(draw, URDF)


def _import_urdf(cli, d, data: bytes):
    f = d / "arm.urdf"
    f.write_bytes(data)
    return run_case(cli, d, ["import-urdf", f, "-o", d / "out.toml"], output=d / "out.toml", file=str(f))


@FUZZ
@given(data=urdf_attribute_edit())
def test_urdf_attribute_values(cli, tmp_path_factory, data):
    _import_urdf(cli, tmp_path_factory.mktemp("urdf"), data)


@FUZZ
@given(data=urdf_damage())
def test_urdf_damaged(cli, tmp_path_factory, data):
    _import_urdf(cli, tmp_path_factory.mktemp("urdf"), data)


def test_urdf_mimic_on_the_chain(cli, tmp_path):
    data = URDF.replace('<dynamics damping="0.5" friction="0.1"/>', '<mimic joint="elbow"/>').encode()
    case = _import_urdf(cli, tmp_path, data)
    assert case.rc == 2 and "joint shoulder" in case.first_error and "field 'mimic'" in case.first_error


# ---- .par -------------------------------------------------------------------------------------
PARS = {name: export_par(load_robot(name)) for name in ("scara", "lwr4")}
_ELEM = re.compile(r"(?<=[{,])([^,{}]*)(?=[,}])")


@st.composite
def par_element_edit(draw):
    text = PARS[draw(st.sampled_from(sorted(PARS)))]
    m = draw(st.sampled_from(list(_ELEM.finditer(text))))
    new = draw(st.sampled_from(ODD + ["t1", "q1", "Pi/0", "1/0", "XX1*", "(", "2**10**10", "__import__('os')"]))
    return (text[: m.start()] + new + text[m.end():]).encode()


@st.composite
def par_damage(draw):
    return _damaged(draw, PARS[draw(st.sampled_from(sorted(PARS)))])


def _import_par(cli, d, data: bytes):
    f = d / "arm.par"
    f.write_bytes(data)
    return run_case(cli, d, ["import-par", f, "-o", d / "out.toml"], output=d / "out.toml", file=str(f))


@FUZZ
@given(data=par_element_edit())
def test_par_elements(cli, tmp_path_factory, data):
    _import_par(cli, tmp_path_factory.mktemp("par"), data)


@FUZZ
@given(data=par_damage())
def test_par_damaged(cli, tmp_path_factory, data):
    _import_par(cli, tmp_path_factory.mktemp("par"), data)
