"""Model selection between nested noise models on the Whittle likelihood (issue 45, item 3).

A Cramér–Rao bound, and an estimator's efficiency, hold only for the model a record follows: on
the ADIS16405 a white + walk fit reads K several times the value a fit with bias instability
reads. So the model is chosen first, by a stated criterion, and the terms are read from it.

The rule
--------
Every candidate (:data:`CANDIDATES`: white + walk; + bias instability; + Gauss–Markov;
+ quantization; all five) is fitted by the tapered Whittle likelihood of
:func:`gyroarray.analysis.whittle.fit_whittle` over **the same** ordinates (one band, one set of
still parts), and the one with the least

    BIC = 2·NLL + p·ln M

is chosen (NLL the Whittle negative log-likelihood at the fit, −log of the exponential density of
the periodogram ordinates; p the parameters; M the ordinates used). Ties (within
:data:`BIC_TIE`) go to the candidate with fewer parameters.

Why BIC, not a likelihood-ratio test or AIC: the nested terms' null values lie on the boundary of
the parameter space (a term's scale 0), where the likelihood ratio is not χ² with the parameter
count as its df (it is a χ̄² mixture, and for Gauss–Markov τ is not identified under the null);
BIC needs no null distribution and is consistent: with M ~ 10⁴–10⁶ ordinates its penalty ln M ≈
9–14 per parameter makes a spurious term win with probability ≈ P(χ²₁ > ln M)/2 ≈ 10⁻³–10⁻⁴,
while AIC's penalty 2 keeps one about 8 % of the time. The cost: a real but weak term needs a
log-likelihood gain of ln M/2 to be kept.

SI inside: rates rad/s, angles rad, times s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gyroarray.analysis.whittle import TAPER, WhittleFit, fit_whittle
from gyroarray.core.errors import InputError

__all__ = ["CANDIDATES", "BIC_TIE", "RULE", "Selection", "bic", "select_model"]

#: The nested candidate models, smallest first (terms of :mod:`gyroarray.analysis.crb`).
CANDIDATES = (("n", "k"), ("n", "k", "b"), ("n", "k", "gm"), ("n", "k", "q"), ("n", "k", "q", "b", "gm"))

#: BIC differences within this [-] are ties, given to the model with fewer parameters.
BIC_TIE = 1e-6

#: The selection rule in words.
RULE = ("least BIC = 2·NLL + p·ln M over the candidates fitted by tapered Whittle ML on the same "
        "ordinates (M of them, p parameters); ties to the fewer parameters")


def bic(fit: WhittleFit) -> float:
    """BIC = 2·NLL + p·ln M of a Whittle fit (NLL its negative log-likelihood, p its parameters,
    M its ordinates) [-]."""
    return 2.0 * fit.nll + len(fit.values) * math.log(fit.n_freq)


def _label(terms) -> str:
    return "+".join(terms)


@dataclass(frozen=True)
class Selection:
    """The model chosen and every candidate's fit.

    Parameters
    ----------
    terms : tuple
        The terms of the chosen model.
    fit : WhittleFit
        Its fit.
    fits : dict
        Candidate label (``"n+k+b"``) -> its :class:`~gyroarray.analysis.whittle.WhittleFit`.
    bic : dict
        Candidate label -> BIC [-].
    failed : dict
        Candidate label -> why it could not be fitted.
    rule : str
        The criterion, in words.
    """

    terms: tuple
    fit: WhittleFit
    fits: dict
    bic: dict
    failed: dict
    rule: str = RULE

    @property
    def label(self) -> str:
        """The chosen model's label (``"n+k+b"``)."""
        return _label(self.terms)

    def to_json_dict(self) -> dict:
        """The selection as JSON (SI values; BIC dimensionless)."""
        best = self.bic[self.label]
        return {"chosen": list(self.terms), "rule": self.rule,
                "candidates": {lab: {"bic": b, "delta_bic": b - best,
                                     "values_si": {p: float(v) for p, v in self.fits[lab].values.items()},
                                     "sigma_si": {p: None if v is None else float(v)
                                                  for p, v in self.fits[lab].sigma.items()}}
                               for lab, b in self.bic.items()},
                "failed": dict(self.failed)}


def select_model(x, dt_s: float, *, parts=None, band_hz=None, candidates=CANDIDATES,
                 taper: float = TAPER, known=()) -> Selection:
    """Choose between nested noise models by BIC on the Whittle likelihood (:data:`RULE`).

    Parameters
    ----------
    x : array_like, shape (n,)
        Rate [rad/s].
    dt_s : float
        Sample step [s].
    parts : sequence of (int, int), optional
        Still parts [start, stop) in samples (default: the whole record).
    band_hz : (float, float), optional
        The band [Hz] every candidate is fitted over (default all frequencies but 0; a
        band-limited fit takes :func:`gyroarray.analysis.whittle.choose_band`'s).
    candidates : sequence of sequence of str, default :data:`CANDIDATES`
        The models compared.
    taper : float, default :data:`TAPER`
        Tukey taper fraction.
    known : sequence of WhittleFit, optional
        Fits already made of these data (the same parts): one with a candidate's terms, this
        band and this taper is used, not refitted (``choose_band``'s pilot).

    Returns
    -------
    Selection
    """
    cands = [tuple(c) for c in candidates]
    if not cands:
        raise InputError("model selection needs at least one candidate model")
    fits, scores, failed = {}, {}, {}
    for terms in cands:
        lab = _label(terms)
        reuse = [f for f in known if f is not None and tuple(f.terms) == terms and f.taper == float(taper)
                 and f.band_hz == (None if band_hz is None else (float(band_hz[0]), float(band_hz[1])))]
        if reuse:
            fits[lab] = reuse[0]
            scores[lab] = bic(reuse[0])
            continue
        try:
            f = fit_whittle(x, dt_s, terms, parts=parts, taper=taper, band_hz=band_hz)
        except InputError as err:
            if len(cands) == 1:
                raise
            failed[lab] = err.message
            continue
        fits[lab] = f
        scores[lab] = bic(f)
    if not fits:
        raise InputError("no candidate noise model could be fitted: " + "; ".join(failed.values()))
    best = min(scores.values())
    near = [lab for lab in scores if scores[lab] - best <= BIC_TIE]
    lab = min(near, key=lambda s: (len(fits[s].values), scores[s]))
    return Selection(terms=fits[lab].terms, fit=fits[lab], fits=fits, bic=scores, failed=failed)
