"""The result of :func:`symoro_gen.diagnostics.diagnose`: effects added, candidates tried, errors
before and after, with ``summary()``, ``to_dict()`` (the JSON contract of the ``diagnose`` command),
``to_markdown()`` and ``write_plots()``."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..identification.result import IdentificationResult
from .plausibility import Plausibility
from .plots import write_plots
from .render import diagnosis_html

__all__ = ["CandidateScore", "Effect", "ResidualReport"]


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _fl(a):
    return [_f(x) for x in np.asarray(a, float).reshape(-1)]


def _num(x) -> str:
    return "?" if x is None else f"{float(x):.4g}"


def _j(j):
    return None if j is None else int(j) + 1


@dataclass(frozen=True)
class CandidateScore:
    """How one candidate family did in one round.

    Attributes
    ----------
    round : int
        1-based round of the loop.
    kind, label, variant : str
    joint, partner : int or None
        0-based.
    score : float or None
        Sum over joints of the fractional decrease of the squared validation error norm
        (``(||rho_j||^2 - ||rho_j'||^2) / ||rho_j||^2``); None when not evaluated.
    p_value : float or None
        F test on the identification data, corrected for serial correlation and for the 1-D search
        (Bonferroni over the grid); compare with ``threshold``.
    z_validation : float or None
        Validation decrease of the weighted squared error, in standard deviations of its null
        distribution (adding useless columns).
    threshold : float or None
        Per-test level (significance / number of candidates this round).
    identifiability : float
        Smallest share of a candidate column's norm outside the span of the current model's columns.
    eligible : bool
        Passed every criterion.
    reason : str
        Why not eligible (empty when eligible).
    search : dict
        Best value of the searched parameter (e.g. ``{"vs": 0.05}``).
    val_rel_err_before, val_rel_err_after : tuple of float
        Validation relative error norms per joint without and with the candidate.
    score_se : float or None
        Standard error of ``score`` (contiguous time blocks of the acceptance data).
    chosen_over : str
        When the one-standard-error rule put it first in its round: over which better-scoring candidate, with
        the scores and the numbers of parameters; empty otherwise.
    """

    round: int
    kind: str
    label: str
    joint: int | None
    partner: int | None
    variant: str
    score: float | None
    p_value: float | None
    z_validation: float | None
    threshold: float | None
    identifiability: float
    eligible: bool
    reason: str
    search: dict = field(default_factory=dict)
    val_rel_err_before: tuple = ()
    val_rel_err_after: tuple = ()
    score_se: float | None = None
    chosen_over: str = ""

    def to_dict(self) -> dict:
        return {"round": self.round, "kind": self.kind, "label": self.label, "joint": _j(self.joint),
                "partner": _j(self.partner), "variant": self.variant, "score": _f(self.score),
                "p_value": _f(self.p_value), "z_validation": _f(self.z_validation),
                "threshold": _f(self.threshold), "identifiability": _f(self.identifiability),
                "eligible": self.eligible, "reason": self.reason,
                "search": {k: _f(v) for k, v in self.search.items()}, "score_se": _f(self.score_se),
                "chosen_over": self.chosen_over or None}


@dataclass(frozen=True, eq=False)
class Effect:
    """An effect added to the model.

    Attributes
    ----------
    kind, label, variant : str
    joint, partner : int or None
        0-based.
    names : tuple of str
        Its columns in the augmented model.
    values, std, rel_std_pct : ndarray
        Identified (final model, the chosen method) values, standard deviations and %sigma.
    physical : dict
        Physical reading (searched parameter, stiffness, delay, gain...).
    score, p_value, z_validation : float
        Evidence when it was added (see :class:`CandidateScore`).
    round : int
        Round of the loop it was added in (0: the friction-law stage).
    reveal : str
        Row signal it shows against; ``reveal_joint`` its joint.
    modulation : str or None
        Modulating signal of a composed effect (:mod:`.compose`: ``abs_tau``, ``abs_dq``, ``step:t=12``,
        ``q_other:q3``...); None for a plain effect.
    selection_frequency : float or None
        Share of the time-blocked folds that select it (the smaller under OLS and WLS weights; for a
        friction law, the share of folds whose held-out block it predicts better than the declared law).
    ci : dict
        Confidence interval ``[low, high]`` of each coefficient (HAC, level ``ci_level``).
    description : str
        The effect in words.
    verdict : str
        ``cause``, ``doubtful`` or ``rejected`` (:func:`.plausibility.verdict`); empty when not rated.
    plausibility : Plausibility or None
        Its rating against the physical priors (:mod:`.plausibility`): ``score`` in [0, 1] and ``reasons``.
    alternatives : tuple of dict
        The next candidates of its round on its joints (``label``, ``kind``, ``joint``, ``score``,
        ``eligible``, ``search``), best first.
    verdict_reason : str
        Why that verdict, in words (with what it fits like and what to check).
    chosen_over : str
        When its round's one-standard-error rule chose it over a better-scoring candidate with more
        parameters: that candidate, the scores and the numbers of parameters; empty otherwise.
    """

    kind: str
    label: str
    variant: str
    joint: int | None
    partner: int | None
    names: tuple
    values: np.ndarray
    std: np.ndarray
    rel_std_pct: np.ndarray
    physical: dict
    score: float
    p_value: float
    z_validation: float
    round: int
    reveal: str
    reveal_joint: int | None
    modulation: str | None = None
    selection_frequency: float | None = None
    ci: dict = field(default_factory=dict)
    description: str = ""
    ci_level: float | None = None
    verdict: str = ""
    plausibility: Plausibility | None = None
    alternatives: tuple = ()
    verdict_reason: str = ""
    chosen_over: str = ""

    def to_dict(self) -> dict:
        return {"kind": self.kind, "joint": _j(self.joint), "partner": _j(self.partner), "variant": self.variant,
                "label": self.label, "description": self.description or self.label,
                "modulation": self.modulation, "selection_frequency": _f(self.selection_frequency),
                "ci": {n: [_f(a), _f(b)] for n, (a, b) in self.ci.items()}, "ci_level": _f(self.ci_level),
                "params": {n: _f(v) for n, v in zip(self.names, self.values)},
                "std": {n: _f(v) for n, v in zip(self.names, self.std)},
                "rel_std_pct": {n: _f(v) for n, v in zip(self.names, self.rel_std_pct)},
                "physical": {k: _f(v) for k, v in self.physical.items()},
                "score": _f(self.score), "p_value": _f(self.p_value), "z_validation": _f(self.z_validation),
                "round": self.round, "verdict": self.verdict or None,
                "verdict_reason": self.verdict_reason or None, "chosen_over": self.chosen_over or None,
                "plausibility": None if self.plausibility is None else {
                    "score": _f(self.plausibility.score), "reasons": list(self.plausibility.reasons)},
                "alternatives": [{**a, "score": _f(a.get("score")), "remaining": _f(a.get("remaining")),
                                  "search": {k: _f(v) for k, v in dict(a.get("search") or {}).items()}}
                                 for a in self.alternatives]}

    def verdict_lines(self) -> list[str]:
        """The verdict in words: ``"doubtful (plausibility 0.07): fits like a 48 ms delay on joint 7 only; ..."``
        and the alternatives of its round (empty when not rated)."""
        if not self.verdict:
            return []
        pl = "" if self.plausibility is None else f" (plausibility {float(self.plausibility.score):.2f})"
        out = [f"{self.verdict}{pl}: {self.verdict_reason}"]
        if self.alternatives:
            out.append("alternatives: " + ", ".join(
                f"{a['label']} (score {_num(a.get('score'))}{', eligible' if a.get('eligible') else ''})"
                for a in self.alternatives))
        return out


@dataclass(frozen=True, eq=False)
class ResidualReport:
    """What the residual says the declared model misses, and how much adding it helps.

    Attributes
    ----------
    robot, method : str
    n_joints : int
    before_rel_err, before_validation_rel_err : ndarray, shape (n,)
        Relative error norms ``||rho_j|| / ||Y_j||`` of the declared model on identification and
        validation data.
    after_rel_err, after_validation_rel_err : ndarray, shape (n,)
        The same with every effect added. Both are on the filtered, decimated system (the papers'
        metric; cut-off and ``n_d`` in ``settings``).
    effects : tuple of Effect
        In the order added.
    tried : tuple of CandidateScore
        Every candidate of every round.
    placebos : tuple of CandidateScore
        The placebo candidates (random smooth columns) of every round.
    structure_before, structure_after : tuple of StructureItem
        Structure tests of the identification residual.
    result_before, result_after : IdentificationResult
    settings : dict
        Significance, hold-out, sources, filter settings...
    warnings : tuple of str
    plot_data : dict
        Arrays for :meth:`write_plots` (not part of the JSON).
    before_validation_rel_err_raw, after_validation_rel_err_raw : ndarray, shape (n,), or None
        Validation relative error norms on the raw measured torque: the model (declared, then with every
        effect) at full rate on the filtered states against the unfiltered torque, every sample.
    unexplained : tuple of UnexplainedItem
    estimator_dependent : tuple of dict
        Effects the loop accepted that only one weighting (OLS or WLS) names in the stability stage: dropped
        from the model ("keep only the common ones"); ``kind``, ``joint`` (1-based),
        ``modulation``, ``label``, ``named_under``, ``selection_frequency`` and ``excludes_zero`` per weighting.
    implausible : tuple of dict
        Eligible candidates the loop did not add because the re-identified model with them had an effect
        with physically impossible parameters (:func:`.candidates.implausible`): ``candidate``, ``round``,
        ``reasons``; and (``round`` 0) the friction-law replacements not applied because implausible
        (:mod:`.plausibility`), with ``law`` and ``plausibility``.
    """

    robot: str
    method: str
    n_joints: int
    before_rel_err: np.ndarray
    before_validation_rel_err: np.ndarray
    after_rel_err: np.ndarray
    after_validation_rel_err: np.ndarray
    effects: tuple
    tried: tuple
    placebos: tuple
    structure_before: tuple
    structure_after: tuple
    result_before: IdentificationResult
    result_after: IdentificationResult
    settings: dict
    warnings: tuple = ()
    plot_data: dict = field(default_factory=dict, repr=False)
    before_validation_rel_err_raw: np.ndarray | None = None
    after_validation_rel_err_raw: np.ndarray | None = None
    unexplained: tuple = ()
    estimator_dependent: tuple = ()
    implausible: tuple = ()
    acceptance: dict = field(default_factory=dict)
    before_validation_rel_err_band: np.ndarray | None = None
    after_validation_rel_err_band: np.ndarray | None = None

    @property
    def unexplained_flagged(self) -> tuple:
        """The joints whose residual holds structure no candidate explains (:mod:`.unexplained`)."""
        return tuple(u for u in self.unexplained if u.flagged)

    def error_basis(self) -> dict:
        """What each error norm is computed on (the JSON ``error_basis``)."""
        st = self.settings if isinstance(self.settings, dict) else {}
        return {
            "rel_err": "||Y_j - W_j chi|| / ||Y_j|| on the filtered, decimated identification system",
            "validation_rel_err": "the same on the filtered, decimated validation system",
            "validation_rel_err_raw": "||tau_j - tau_hat_j|| / ||tau_j||: the model at full rate on the filtered "
                                      "states against the raw measured validation torque, every sample",
            "cutoff_hz": st.get("cutoff_hz"), "n_d": st.get("n_d"),
            "rows_identification": st.get("rows_identification"), "rows_validation": st.get("rows_validation"),
            "samples_validation": st.get("samples_validation"),
        }

    # ------------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON contract: ``before``/``after`` {``rel_err``, ``validation_rel_err``, ``validation_rel_err_raw``},
        ``error_basis`` (what each is computed on), ``effects`` (order
        added: ``kind``, ``joint`` 1-based or null, ``params``, ``score``...), ``tried`` (every candidate
        with its score), plus ``placebos``, ``structure``, ``settings``, ``warnings``."""
        return {
            "robot": self.robot,
            "method": self.method,
            "n_joints": self.n_joints,
            "before": self._errors(self.before_rel_err, self.before_validation_rel_err,
                                   self.before_validation_rel_err_raw, self.before_validation_rel_err_band),
            "after": self._errors(self.after_rel_err, self.after_validation_rel_err, self.after_validation_rel_err_raw,
                                  self.after_validation_rel_err_band),
            "acceptance": dict(self.acceptance),
            "error_basis": self.error_basis(),
            "effects": [e.to_dict() for e in self.effects],
            "unexplained": [u.to_dict() for u in self.unexplained_flagged],
            "unexplained_all": [{**u.to_dict(), "threshold": _f(u.threshold), "flagged": u.flagged}
                                for u in self.unexplained],
            "estimator_dependent": [dict(d) for d in self.estimator_dependent],
            "implausible": [dict(d) for d in self.implausible],
            "tried": [c.to_dict() for c in self.tried],
            "placebos": [c.to_dict() for c in self.placebos],
            "structure": {"before": [s.to_dict() for s in self.structure_before if s.significant],
                          "after": [s.to_dict() for s in self.structure_after if s.significant]},
            "settings": self.settings,
            "warnings": list(self.warnings),
        }

    def error_rows(self) -> list[tuple[str, np.ndarray]]:
        """Labelled rows of the error table (the labels say which metric)."""
        rows = [("identification, before", self.before_rel_err),
                ("identification, after", self.after_rel_err),
                ("validation, before", self.before_validation_rel_err),
                ("validation, after", self.after_validation_rel_err)]
        if self.before_validation_rel_err_raw is not None and self.after_validation_rel_err_raw is not None:
            rows += [("validation, before (raw torque)", self.before_validation_rel_err_raw),
                     ("validation, after (raw torque)", self.after_validation_rel_err_raw)]
        return rows

    @staticmethod
    def _errors(ident, valid, valid_raw, band=None) -> dict:
        out = {"rel_err": _fl(ident), "validation_rel_err": _fl(valid)}
        if valid_raw is not None:
            out["validation_rel_err_raw"] = _fl(valid_raw)
        if band is not None:
            out["validation_rel_err_band"] = [_fl(b) for b in np.asarray(band)]
        return out

    def best_tried(self, round: int = 1, k: int = 10) -> list[CandidateScore]:
        """The ``k`` best-scored candidates of a round."""
        cs = [c for c in self.tried if c.round == round and c.score is not None]
        return sorted(cs, key=lambda c: -c.score)[:k]

    def _error_table(self) -> list[str]:
        n = self.n_joints
        head = "            " + "".join(f"{'joint ' + str(j + 1):>10}" for j in range(n))
        rows = [head]
        table = [("ident before", self.before_rel_err), ("ident after", self.after_rel_err),
                 ("valid before", self.before_validation_rel_err), ("valid after", self.after_validation_rel_err)]
        if self.before_validation_rel_err_raw is not None and self.after_validation_rel_err_raw is not None:
            table += [("raw before", self.before_validation_rel_err_raw),
                      ("raw after", self.after_validation_rel_err_raw)]
        for lab, a in table:
            rows.append(f"{lab:<12}" + "".join(f"{x:>10.4f}" for x in a))
        b0 = self.before_validation_rel_err_band
        if b0 is not None:
            lvl = 100 * float(self.acceptance.get("band_level", 0.95))
            rows.append(f"validation per joint, before -> after [{lvl:.0f} % block-bootstrap band of before]:")
            for j in range(n):
                a, b = self.before_validation_rel_err[j], self.after_validation_rel_err[j]
                flag = "  WORSE beyond the band" if np.isfinite(b0[j, 1]) and b > b0[j, 1] else ""
                rows.append(f"  joint {j + 1}: {a:.4f} -> {b:.4f}  [{b0[j, 0]:.4f}, {b0[j, 1]:.4f}]{flag}")
        acc = self.acceptance
        if acc:
            rows.append(f"acceptance ({acc.get('data', '?')}; the validation data are not read by it), per joint "
                        "declared -> final [band of declared]:")
            for j, (a, b, bd) in enumerate(zip(acc.get("declared_rel_err", []), acc.get("final_rel_err", []),
                                               acc.get("declared_rel_err_band", []))):
                rows.append(f"  joint {j + 1}: {a:.4f} -> {b:.4f}  [{bd[0]:.4f}, {bd[1]:.4f}]")
        return rows

    def _repr_html_(self) -> str:
        """Tables of the diagnosis (Jupyter)."""
        return diagnosis_html(self)

    def summary(self, n_tried: int = 8) -> str:
        """Errors before/after, the effects added with their parameters and %sigma, the best candidates of
        each round, structure left, numbered warnings."""
        L = [f"Residual diagnosis of {self.robot} (IDIM-{self.method.upper()}), "
             f"{len(self.effects)} effect(s) added",
             f"validation: {self.settings.get('validation', '?')}",
             "", "Relative error norms ||rho_j||/||Y_j||: 'ident'/'valid' on the filtered, decimated system "
             f"(cut-off {_num(self.settings.get('cutoff_hz'))} Hz, n_d = {self.settings.get('n_d', '?')}); 'raw' on the "
             "raw measured validation torque (model at full rate on the filtered states)"]
        L += self._error_table()
        L.append("")
        if self.effects:
            L.append("Effects added (in order):")
            for i, e in enumerate(self.effects, 1):
                who = "all joints" if e.joint is None else f"joint {e.joint + 1}"
                if e.partner is not None:
                    who += f" ({e.variant}, with joint {e.partner + 1})"
                ev = ", ".join(x for x in (
                    f"score {e.score:.3f}" if _f(e.score) is not None else "",
                    f"p = {e.p_value:.2e}" if _f(e.p_value) is not None else "",
                    f"z_val = {e.z_validation:.1f}" if _f(e.z_validation) is not None else "",
                    f"selected in {100 * e.selection_frequency:.0f} % of the folds"
                    if e.selection_frequency is not None else "") if x)
                tag = f" [{e.verdict}]" if e.verdict else ""
                L.append(f" {i}. {e.kind} on {who}" + (f" ({e.modulation})" if e.modulation else "") + f"{tag}: {ev}")
                if e.description:
                    L.append(f"      {e.description}")
                if e.chosen_over:
                    L.append(f"      {e.chosen_over}")
                L += [f"      {x}" for x in e.verdict_lines()]
                for n, v, p in zip(e.names, e.values, e.rel_std_pct):
                    L.append(f"      {n:<28}{v:>12.4g}  %sigma {p:8.2f}")
                if e.physical:
                    L.append("      " + ", ".join(f"{k} = {v:.4g}" for k, v in e.physical.items()))
        else:
            L.append("No effect added: no candidate was significant on the identification data and "
                     "better than noise on the held-out acceptance data (the end of each identification experiment).")
        for key in ("sign_smoothing", "static_at_rest", "joint_zero"):
            for line in (self.settings.get(key) or []) if isinstance(self.settings, dict) else []:
                L.append(f"Note: {line}")
        rounds = sorted({c.round for c in self.tried})
        for r in rounds:
            best = self.best_tried(r, n_tried)
            if not best:
                continue
            L.append("")
            L.append(f"Round {r}: best candidates by validation score")
            L.append(f"  {'candidate':<22}{'score':>8}{'p':>11}{'thresh':>10}{'z_val':>8}  verdict")
            for c in best:
                L.append(f"  {c.label + (' ' + c.variant if c.variant and c.kind != 'coupling' else ''):<22}"
                         f"{c.score:>8.3f}{c.p_value:>11.2e}{c.threshold:>10.1e}{c.z_validation:>8.1f}  "
                         f"{'eligible' if c.eligible else c.reason}")
            L += [f"  {c.label}: {c.chosen_over}" for c in self.tried if c.round == r and c.chosen_over]
        L += self._estimator_lines()
        L += self._unexplained_lines()
        left = [s for s in self.structure_after if s.significant]
        if left:
            L.append("")
            L.append("Structure left in the identification residual (explained variance, Bonferroni p):")
            for s in sorted(left, key=lambda s: -s.eta2)[:12]:
                L.append(f"  joint {s.joint + 1} vs {s.label}: {100 * s.eta2:.1f} %, p = {s.p_value:.1e}")
        if self.warnings:
            L.append("")
            L.append("Warnings:")
            L += [f"[{i}] {w}" for i, w in enumerate(self.warnings, 1)]
        return "\n".join(L)

    def _estimator_lines(self) -> list[str]:
        if not self.estimator_dependent:
            return []
        return ["", "Estimator-dependent (named under one weighting only, dropped from the model):"] + [
            f"  {d['label']}: named under {d['named_under']} weights only (selected in "
            + " / ".join(f"{100 * f:.0f} %" for f in d["selection_frequency"].values()) + " of the folds under "
            + " / ".join(d["selection_frequency"]) + ")" for d in self.estimator_dependent]

    def _unexplained_lines(self) -> list[str]:
        if not self.unexplained:
            return []
        L = ["", "Structure left that no candidate explains (out-of-fold R^2 of boosted trees on the final "
                 "residual; flagged above a threshold calibrated on block-permuted residuals):"]
        flagged = self.unexplained_flagged
        for u in flagged:
            L.append(f"  joint {u.joint}: share {u.share:.2f} of the residual variance (threshold "
                     f"{u.threshold:.2f}), depends on {', '.join(u.signals) or '?'}")
        if not flagged:
            L.append("  none: every joint's residual is below its threshold ("
                     + ", ".join(f"j{u.joint} {u.share:.2f}/{u.threshold:.2f}" for u in self.unexplained) + ")")
        return L

    def to_markdown(self, plots: list | None = None) -> str:
        """A Markdown report (tables of errors, effects, candidates; links to plots)."""
        n = self.n_joints
        L = [f"# Residual diagnosis: {self.robot} (IDIM-{self.method.upper()})", "",
             f"Validation: {self.settings.get('validation', '?')}", "",
             "| | " + " | ".join(f"joint {j + 1}" for j in range(n)) + " |",
             "|---|" + "---:|" * n]
        for lab, a in self.error_rows():
            L.append(f"| {lab} | " + " | ".join(f"{x:.4f}" for x in a) + " |")
        L.append("")
        L.append(f"Rows without '(raw torque)': relative error norms on the filtered, decimated system (cut-off "
                 f"{_num(self.settings.get('cutoff_hz'))} Hz, n_d = {self.settings.get('n_d', '?')}); '(raw torque)': "
                 "the model at full rate on the filtered states against the raw measured torque, every sample.")
        L.append("")
        L.append("## Effects added")
        if not self.effects:
            L.append("None.")
        for i, e in enumerate(self.effects, 1):
            who = "all joints" if e.joint is None else f"joint {e.joint + 1}"
            if e.partner is not None:
                who += f" ({e.variant} with joint {e.partner + 1})"
            L.append(f"{i}. **{e.kind}** on {who}" + (f" (modulated by {e.modulation})" if e.modulation else "")
                     + f" - {e.description or e.label}; score {_num(_f(e.score))}, p = {_num(_f(e.p_value))}, "
                     f"z_val = {_num(_f(e.z_validation))}, selection frequency {_num(e.selection_frequency)}"
                     + (f"; verdict **{e.verdict}**" if e.verdict else ""))
            L += [f"   - {x}" for x in e.verdict_lines()]
            for nme, v, p in zip(e.names, e.values, e.rel_std_pct):
                L.append(f"   - `{nme}` = {v:.4g} (%sigma {p:.2f})")
            for k, v in e.physical.items():
                L.append(f"   - {k} = {v:.4g}")
        notes = [line for key in ("sign_smoothing", "static_at_rest", "joint_zero")
                 for line in ((self.settings.get(key) or []) if isinstance(self.settings, dict) else [])]
        if notes:
            L.append("")
            L += [f"Note: {line}" for line in notes]
        L.append("")
        L.append("## Candidates (best 10 of each round)")
        for r in sorted({c.round for c in self.tried}):
            L.append(f"### Round {r}")
            L.append("| candidate | score | p | threshold | z_val | verdict |")
            L.append("|---|---:|---:|---:|---:|---|")
            for c in self.best_tried(r, 10):
                L.append(f"| {c.label} {c.variant} | {c.score:.3f} | {c.p_value:.2e} | {c.threshold:.1e} | "
                         f"{c.z_validation:.1f} | {'eligible' if c.eligible else c.reason} |")
        if self.estimator_dependent:
            L.append("")
            L.append("## Estimator-dependent effects (dropped)")
            L += [x.strip() for x in self._estimator_lines()[2:]]
        if self.unexplained:
            L.append("")
            L.append("## Structure left that no candidate explains")
            L += [x.strip() for x in self._unexplained_lines()[2:]]
        if plots:
            L.append("")
            L.append("## Plots")
            for p in plots:
                L.append(f"![{Path(p).stem}]({p})")
        if self.warnings:
            L.append("")
            L.append("## Warnings")
            L += [f"{i}. {w}" for i, w in enumerate(self.warnings, 1)]
        return "\n".join(L) + "\n"

    def write_plots(self, folder, *, force: bool = False) -> list[Path]:
        """Residual before/after each effect against the signal that revealed it, and the error norms
        (needs matplotlib; Agg backend). Returns the files written (empty without matplotlib). Existing
        ``diagnosis-*.png`` files symoro-gen did not write are replaced only with ``force``."""
        return write_plots(self, folder, force=force)

    def __repr__(self) -> str:
        return (f"ResidualReport(robot={self.robot!r}, method={self.method!r}, "
                f"effects={[e.label for e in self.effects]})")
