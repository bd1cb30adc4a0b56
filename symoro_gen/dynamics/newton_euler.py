"""Customized symbolic recursive Newton-Euler giving the regressor IDM_st.

Forward recursion once (angular velocity, angular acceleration, linear acceleration of
every frame origin, gravity included as an acceleration of the base); then, for each
standard parameter, its elementary wrench on its own link is carried back towards the
base and projected on every joint axis it meets (backward contributions per parameter).
Intermediate variables are kept as named symbols (see :mod:`.graph`).

References: the customised recursive Newton-Euler algorithm of [KK1987] (intermediate variables, zero
terms dropped) and [KD2002] ch. 9 (inverse dynamic model linear in the standard parameters, the MDH
frames of [KK1986]); the drive-chain columns ``IA ddq``, ``FV dq``, ``FS sign(dq)``, ``OFF`` are the
rotor inertia, friction and offset terms of the IDM of [GB-gains] eq. 1-8.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from sympy.core.add import _addsort
from sympy.core.mul import _mulsort

from ..description.mdh import constant_rotation, joint_sign, position, rot_z
from ..description.model import PRISMATIC, REVOLUTE, RobotDescription, ddq_symbol, dq_symbol, q_symbol
from ..params import INERTIAL_KINDS, param_name
from .graph import ExprGraph, GraphBuilder


@dataclass(frozen=True)
class SymbolicRegressor:
    """The standard regressor IDM_st (n x n_st) and the payload one (n x 10), as a graph.

    ``graph.outputs`` maps ``(i, name)`` to the entry on joint row ``i`` (0-based, in
    ``joint_frames`` order) of the column of parameter ``name`` (standard or payload).
    """

    robot: RobotDescription
    graph: ExprGraph
    standard_names: tuple[str, ...]
    payload_names: tuple[str, ...]
    joint_frames: tuple[int, ...]
    #: rows before the joint rows: 6 for a floating base (its wrench: force then moment about the base
    #: origin, in base axes; joint row ``i`` is then output row ``6 + i``), 0 for a fixed base
    base_rows: int = 0

    def column(self, name: str) -> dict[int, sp.Expr]:
        return {i: e for (i, n), e in self.graph.outputs.items() if n == name}


_ZERO = sp.S.Zero


@dataclass(frozen=True)
class BaseMotion:
    """The motion of a floating base (frame 0) as inputs of the recursion ([KD2002] ch. 9: the base's
    velocity and acceleration start the forward recursion instead of zero; gravity enters as an upward
    acceleration of the base, as for a fixed base).

    ``w``, ``wd``: angular velocity and acceleration of frame 0 in frame 0; ``vd``: the linear
    acceleration of origin 0 minus gravity, in frame 0 (expressions of the input symbols, named in the
    graph). ``q``, ``dq``, ``ddq``: the base's input symbols, put before the joints' in the graph's
    inputs. Built by :func:`symoro_gen.dynamics.floating.base_motion`.
    """

    w: tuple[sp.Expr, sp.Expr, sp.Expr]
    wd: tuple[sp.Expr, sp.Expr, sp.Expr]
    vd: tuple[sp.Expr, sp.Expr, sp.Expr]
    q: tuple[sp.Symbol, ...]
    dq: tuple[sp.Symbol, ...]
    ddq: tuple[sp.Symbol, ...]


def _diff(x, y):
    """``x - y`` without building the products that are exactly zero (same result as sympy's)."""
    if y is _ZERO:
        return x
    return -y if x is _ZERO else _add([x, -y])


_MUL = sp.Mul  # what ``a * b`` calls for sympy expressions, without the operator's sympify wrappers


def _monomial(x):
    """``(coefficient or None, symbols)`` when ``x`` is a non-zero number, a symbol, or a product of one
    optional number and distinct symbols (each to the power 1); ``None`` otherwise."""
    if x.is_Symbol:
        return None, (x,)
    if x.is_Mul:
        args = x.args
        if args[0].is_Number:
            coeff, rest = args[0], args[1:]
        else:
            coeff, rest = None, args
        return (coeff, rest) if all(r.is_Symbol for r in rest) else None
    if x.is_Number and x and x.is_finite:
        return x, ()
    return None


def _mul(a, b):
    """``Mul(a, b)``; when both factors are monomials (:func:`_monomial`) with distinct symbols and at most
    one numeric coefficient, the product is built as ``Mul.flatten`` orders it (the number first, then the
    symbols in ``_mulsort`` order) without flatten, which multiplies a float by 1 and asks the new Float
    whether it is zero: sympy deduces all the facts of each new Float (~0.2 ms), most of the cost of general
    chains (floats from sin/cos of arbitrary alpha; ``R[i, k] f[k]`` is ``float * C_j * F``). Any other case:
    ``sympy.Mul``. The same expression either way (tests/baseparams/test_generation_speed.py)."""
    ma, mb = _monomial(a), _monomial(b)
    if ma is None or mb is None:
        return _MUL(a, b)
    (ca, sa), (cb, sb) = ma, mb
    if ca is not None and cb is not None:
        return _MUL(a, b)
    syms = list(sa + sb)
    if len(syms) == 0 or len(set(syms)) != len(syms):
        return _MUL(a, b)
    coeff = ca if ca is not None else cb
    if coeff is not None and coeff == 1:  # flatten drops an exact 1
        return _MUL(a, b)
    if coeff is None and len(syms) == 1:
        return syms[0]
    _mulsort(syms)
    return _MUL._from_args(syms if coeff is None else [coeff, *syms])


def _add(terms: list) -> sp.Expr:
    """``Add(*terms)``; built directly, as ``Add.flatten`` orders it (``_addsort``), when no two terms have the
    same non-numeric part and none is a number or a sum: flatten would rebuild every ``float * symbol``
    term with a new Float (see :func:`_mul`). Any other case: ``sympy.Add``."""
    if len(terms) == 1:
        return terms[0]
    seen = set()
    for t in terms:
        if t.is_Mul:
            args = t.args
            key = args[1:] if (args[0].is_Float or args[0].is_Rational) else args
        elif t.is_Symbol or isinstance(t, sp.Function) or (t.is_Pow and not t.base.is_number):
            key = (t,)
        else:
            return sp.Add(*terms)
        if key in seen:
            return sp.Add(*terms)
        seen.add(key)
    out = list(terms)
    _addsort(out)
    return sp.Add._from_args(out)


def _plus(x, y) -> sp.Expr:
    """``x + y`` as one :func:`_add` of the terms of both (``Add.flatten`` flattens nested sums the same way)."""
    if x is _ZERO:
        return y
    if y is _ZERO:
        return x
    return _add([*sp.Add.make_args(x), *sp.Add.make_args(y)])


def _prod(a, b):
    return _ZERO if a is _ZERO or b is _ZERO else _mul(a, b)


def _dot(pairs) -> sp.Expr:
    """``sum(a * b)`` as one ``Add`` of the non-zero products (one flatten instead of one per term)."""
    terms = [_mul(a, b) for a, b in pairs if a is not _ZERO and b is not _ZERO]
    return _add(terms) if len(terms) > 1 else (terms[0] if terms else sp.Add())


def _cross(a, b):
    a = [sp.sympify(x) for x in a]
    return [_diff(_prod(a[1], b[2]), _prod(a[2], b[1])), _diff(_prod(a[2], b[0]), _prod(a[0], b[2])),
            _diff(_prod(a[0], b[1]), _prod(a[1], b[0]))]


def _matvec(M, v):
    return [_dot((M[i, k], v[k]) for k in range(3)) for i in range(3)]


def _matTvec(M, v):
    return [_dot((M[k, i], v[k]) for k in range(3)) for i in range(3)]


def _inertia_moment(kind: str, wd, p) -> list:
    """Moment E_kind wd + w x (E_kind w) of a unit inertia component, from the products p of w."""
    wdx, wdy, wdz = wd
    return {
        "XX": [wdx, p["xz"], -p["xy"]],
        "XY": [wdy - p["xz"], wdx + p["yz"], p["xx"] - p["yy"]],
        "XZ": [wdz + p["xy"], p["zz"] - p["xx"], wdx - p["yz"]],
        "YY": [-p["yz"], wdy, p["xy"]],
        "YZ": [p["yy"] - p["zz"], wdz - p["xy"], wdy + p["xz"]],
        "ZZ": [p["yz"], -p["xz"], wdz],
    }[kind]




def gravity_symbols(robot: RobotDescription) -> dict[sp.Symbol, float]:
    """Symbols ``G1, G2, G3`` (SYMORO's names) for the non-zero components of ``robot.gravity``.

    Returns
    -------
    dict
        ``symbol -> value`` for each non-zero gravity component (x, y, z of frame 0).
    """
    return {sp.Symbol(f"G{i + 1}", real=True): float(x) for i, x in enumerate(robot.gravity) if x != 0}


def build_regressor(robot: RobotDescription, *, progress=None, symbolic_gravity: bool = False,
                    columns=None, base: BaseMotion | None = None) -> SymbolicRegressor:
    """Symbolic standard + payload regressor of ``robot`` by customized Newton-Euler ([KK1987];
    [KD2002] ch. 9: ``Gamma = IDM_st(q, dq, ddq) chi_st``, IDM of [GB-gains] eq. 1-8).

    Parameters
    ----------
    robot : RobotDescription
    symbolic_gravity : bool
        Keep the non-zero gravity components as the symbols of :func:`gravity_symbols`
        (graph inputs) instead of numbers; used to write regrouping relations exactly.
    progress : callable, optional
        Called as ``progress(stage, j)`` per link (for progress bars).
    columns : collection of str, optional
        Only these parameter columns (standard or payload names) are built; the others are left out of
        ``graph.outputs`` (the exact base-parameter solve needs a few columns, not the whole model).
    base : BaseMotion, optional
        The motion of a floating base (``robot.floating``; :mod:`symoro_gen.dynamics.floating` builds it):
        the recursion starts from it, every wrench is carried to frame 0 and the 6 base-wrench rows come
        before the joint rows.

    Returns
    -------
    SymbolicRegressor
    """
    if robot.floating != (base is not None):
        raise ValueError(f"{robot.file}: base = {robot.base!r}: " + (
            "the fixed-base model does not apply (symoro_gen.dynamics.floating.build_floating_regressor builds "
            "it; `generate` and load_model(<robot file>) take the file, docs/floating-base.md)" if robot.floating
            else "a fixed base has no base motion"))
    if base is not None and symbolic_gravity:
        raise ValueError(f"{robot.file}: a floating base takes gravity through its orientation, not as symbols")
    ne = _NewtonEuler(robot, symbolic_gravity, base)
    ne.forward(progress)
    ne.backward(progress, columns)
    joint_frames = ne.joint_frames
    bq, bdq, bddq = (base.q, base.dq, base.ddq) if base is not None else ((), (), ())
    inputs = bq + tuple(q_symbol(f) for f in joint_frames) + bdq + tuple(dq_symbol(f) for f in joint_frames)
    inputs += bddq + tuple(ddq_symbol(f) for f in joint_frames) + robot.geometry_symbols
    if symbolic_gravity:
        inputs += tuple(gravity_symbols(robot))
    graph = ExprGraph(inputs, tuple(ne.g.defs), ne.outputs)
    return SymbolicRegressor(robot, graph, robot.standard_names, robot.payload_names, joint_frames,
                             6 if base is not None else 0)


class _NewtonEuler:
    """The customized Newton-Euler recursion of one robot, its intermediate variables named in the graph
    builder ``g`` in the order the recursion meets them (that order is the generated code's)."""

    def __init__(self, robot: RobotDescription, symbolic_gravity: bool, base: BaseMotion | None = None) -> None:
        self.robot = robot
        self.g = GraphBuilder()
        self.rows = robot.rows
        self.joint_frames = tuple(r.j for r in robot.joints)
        self.floating = base is not None
        offset = 6 if self.floating else 0  # a floating base's wrench rows come first
        self.row_of = {f: i + offset for i, f in enumerate(self.joint_frames)}
        self.R: dict[int, sp.Matrix] = {}  # ant_R_j (entries simplified: named sin/cos)
        self.P: dict[int, list] = {}  # ant_P_j
        self.frame_transforms()
        # the sign of each joint variable (sympy.diff of theta or r), once per row: carry() asks it at every step
        self.sign = {row.j: joint_sign(row) for row in self.rows if row.sigma in (REVOLUTE, PRISMATIC)}
        zero = [sp.Integer(0)] * 3
        self.w: dict[int, list] = {0: zero}
        self.wd: dict[int, list] = {0: zero}
        # gravity enters as an upward acceleration of the base
        if symbolic_gravity:
            gsym = {int(s.name[1:]) - 1: s for s in gravity_symbols(robot)}
            self.vd: dict[int, list] = {0: [-gsym[i] if i in gsym else sp.Integer(0) for i in range(3)]}
        else:
            self.vd = {0: [sp.Integer(int(-x)) if float(x).is_integer() else sp.Float(-x) for x in robot.gravity]}
        if base is not None:
            self.w[0], self.wd[0] = list(base.w), list(base.wd)
            self.vd[0] = self.g.vec(base.vd, "vd0")
        self.U: dict[int, sp.Matrix] = {}
        self.WW: dict[int, dict[str, sp.Expr]] = {}
        self.outputs: dict[tuple[int, str], sp.Expr] = {}

    def frame_transforms(self) -> None:
        """Per-frame rotation ``ant_R_j`` and position ``ant_P_j``."""
        g = self.g
        for row in self.rows:
            Rc = constant_rotation(row)
            th = row.theta
            if th.free_symbols - set(self.robot.geometry_symbols) or not th.is_number:
                S = g.name(sp.sin(th), f"S{row.j}")
                C = g.name(sp.cos(th), f"C{row.j}")
                Rz = sp.Matrix([[C, -S, 0], [S, C, 0], [0, 0, 1]])
            else:
                Rz = rot_z(th)
            self.R[row.j] = (Rc * Rz).applyfunc(sp.expand)
            pos = position(row)
            self.P[row.j] = [g.name(sp.expand(pos[i]), f"P{row.j}{'xyz'[i]}") for i in range(3)]

    def products(self, j: int) -> dict[str, sp.Expr]:
        """The six products of angular-velocity components of frame j, named once."""
        if j not in self.WW:
            g = self.g
            wx, wy, wz = self.w[j]
            self.WW[j] = {
                "xx": g.name(wx * wx, f"WW{j}xx"),
                "yy": g.name(wy * wy, f"WW{j}yy"),
                "zz": g.name(wz * wz, f"WW{j}zz"),
                "xy": g.name(wx * wy, f"WW{j}xy"),
                "xz": g.name(wx * wz, f"WW{j}xz"),
                "yz": g.name(wy * wz, f"WW{j}yz"),
            }
        return self.WW[j]

    def u_matrix(self, j: int) -> sp.Matrix:
        """U_j = skew(wd_j) + skew(w_j)^2, entries named."""
        if j in self.U:
            return self.U[j]
        Wd = self.wd[j]
        p = self.products(j)
        m = sp.Matrix(
            [
                [-p["yy"] - p["zz"], p["xy"] - Wd[2], p["xz"] + Wd[1]],
                [p["xy"] + Wd[2], -p["xx"] - p["zz"], p["yz"] - Wd[0]],
                [p["xz"] - Wd[1], p["yz"] + Wd[0], -p["xx"] - p["yy"]],
            ]
        )
        names = [["XX", "XY", "XZ"], ["YX", "YY", "YZ"], ["ZX", "ZY", "ZZ"]]
        self.U[j] = sp.Matrix(3, 3, lambda a, b: self.g.name(m[a, b], f"U{j}{names[a][b]}"))
        return self.U[j]

    def forward(self, progress) -> None:
        """Angular velocity, angular acceleration and linear acceleration of every frame origin."""
        g, w, wd, vd, P = self.g, self.w, self.wd, self.vd, self.P
        for row in self.rows:
            j, a = row.j, row.ant
            Rm = self.R[j]
            wa = _matTvec(Rm, w[a])
            wa = g.vec(wa, f"wi{j}")
            wda = g.vec(_matTvec(Rm, wd[a]), f"wdi{j}")
            # acceleration of origin j in frame ant, then rotated
            if a == 0 and not self.floating:
                acc_a = list(vd[0])
            else:
                Ua = self.u_matrix(a)
                acc_a = [vd[a][i] + _dot((Ua[i, k], P[j][k]) for k in range(3)) for i in range(3)]
                acc_a = g.vec(acc_a, f"va{j}")
            vj = g.vec(_matTvec(Rm, acc_a), f"vd{j}")
            if row.sigma == REVOLUTE:
                sg = self.sign[j]
                qd, qdd = sg * dq_symbol(j), sg * ddq_symbol(j)
                w[j] = [wa[0], wa[1], g.name(wa[2] + qd, f"w{j}z")]
                wd[j] = g.vec([wda[0] + qd * wa[1], wda[1] - qd * wa[0], wda[2] + qdd], f"wd{j}")
                vd[j] = vj
            elif row.sigma == PRISMATIC:
                sg = self.sign[j]
                qd, qdd = sg * dq_symbol(j), sg * ddq_symbol(j)
                w[j], wd[j] = wa, wda
                # + 2 w x (qd z) + qdd z
                vd[j] = g.vec([vj[0] + 2 * qd * wa[1], vj[1] - 2 * qd * wa[0], vj[2] + qdd], f"vd{j}")
            else:
                w[j], wd[j], vd[j] = wa, wda, vj
            if progress:
                progress("forward", j)

    def add(self, i: int, name: str, e) -> None:
        e = sp.sympify(e)
        if e != 0:
            self.outputs[(i, name)] = self.outputs.get((i, name), 0) + e

    def carry(self, k: int, name: str, f: list, n: list) -> None:
        """Project the wrench (f, n) of link k on joint k, then carry it to the base."""
        rows, sign, row_of = self.rows, self.sign, self.row_of
        j = k
        if j == 0:  # the floating base's own link
            self.add_base(name, f, n)
        while j != 0:
            row = rows[j - 1]
            if row.sigma == REVOLUTE:
                self.add(row_of[j], name, sign[j] * n[2])
            elif row.sigma == PRISMATIC:
                self.add(row_of[j], name, sign[j] * f[2])
            a = row.ant
            if a == 0 and not self.floating:
                break
            # is anything upstream a joint (or a floating base)?  if not, stop.
            if not self.floating and not any(rows[x - 1].is_moving for x in self.robot.ancestors(j)):
                break
            Rm = self.R[j]
            fa = self.g.vec(_matvec(Rm, f), f"F{name}_{a}")
            cr = _cross(self.P[j], fa)
            na = self.g.vec([_plus(x, y) for x, y in zip(_matvec(Rm, n), cr)], f"N{name}_{a}")
            f, n, j = fa, na, a
            if j == 0:
                self.add_base(name, f, n)

    def add_base(self, name: str, f: list, n: list) -> None:
        """A wrench in frame 0 (moment about origin 0) added to the 6 base-wrench rows of a floating base."""
        for i in range(3):
            self.add(i, name, f[i])
            self.add(3 + i, name, n[i])

    def backward(self, progress, columns) -> None:
        """The elementary wrench of every standard (and payload) parameter on its link, carried back and
        projected on the joint axes; the drive-chain columns of every moving joint."""
        robot = self.robot
        links = [(0, False)] if self.floating else []  # a floating base's link: its 10 inertial parameters
        links += [(row.j, row.is_moving) for row in self.rows]
        for k, moving in links:
            is_payload = robot.payload is not None and k == robot.payload
            if k != 0 and not moving and not is_payload:
                continue
            Uk = self.u_matrix(k)
            Wd, V = self.wd[k], self.vd[k]
            for kind in INERTIAL_KINDS:
                name = param_name(kind, k)
                if columns is not None and name not in columns:
                    continue
                if kind in INERTIAL_KINDS[:6]:
                    # N = E wd + w x (E w), written with the named products of w
                    n_ = _inertia_moment(kind, Wd, self.products(k))
                    f_ = [sp.Integer(0)] * 3
                elif kind == "M":
                    f_, n_ = list(V), [sp.Integer(0)] * 3
                else:
                    e = {"MX": [1, 0, 0], "MY": [0, 1, 0], "MZ": [0, 0, 1]}[kind]
                    f_ = [Uk[i, "XYZ".index(kind[1])] for i in range(3)]
                    n_ = _cross(e, V)
                n_ = self.g.vec(n_, f"n{name}_")
                self.carry(k, name, f_, n_)
            if moving:
                row = self.rows[k - 1]
                i = self.row_of[k]
                extra = {"IA": ddq_symbol(k), "FV": dq_symbol(k), "FS": sp.sign(dq_symbol(k)), "OFF": sp.Integer(1)}
                for kind in row.drive:
                    if columns is None or param_name(kind, k) in columns:
                        self.add(i, param_name(kind, k), extra[kind])
            if progress:
                progress("backward", k)
