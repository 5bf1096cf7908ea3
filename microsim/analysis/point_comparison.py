"""Model versus table on values that are not the cells (docs/conventions.md §7): the metrics that
the judges of the points (:mod:`microsim.analysis.judge_points`) and of the retro rings
(:mod:`microsim.analysis.judge_retro`) share, each judge adding its own rules and statistics.
Neither points nor rings have an albedo: the albedo sums the cells.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from microsim.analysis.selection import config_degrees, extra_selection
from microsim.core.table_noise import chi2_bounds

#: a point whose standard error is under this fraction of its value has no spread (every path adds
#: the same, as on a Lambertian plane): the model must equal it to this fraction
EXACT_POINT = 1e-9


@dataclass
class PointComparison:
    """Model and simulation at a table's points or on its retro rings (``on``: the judge's word),
    with the metrics of conventions §7 but the albedo's."""

    #: what one judged value is, and the JSON key of how many were judged (the judge's)
    unit: ClassVar[str]
    counted: ClassVar[str]

    model_name: str
    params: dict
    order: str
    on: str
    theta_i: np.ndarray
    phi_i: np.ndarray
    model: np.ndarray  # (n_i, n) the model at each point, or averaged over each ring
    sim: np.ndarray  # (n_i, n)
    stderr: np.ndarray  # (n_i, n)
    judged: np.ndarray  # (n_i, n) bool: the points compared, the rings with signal
    exact: np.ndarray  # (n_i, n) bool: the judged points without spread (EXACT_POINT)
    z: np.ndarray  # (n_i, n) (table - model) / standard error (of an exact point: EXACT_POINT of its value)
    #: (n_i, n) each judged point's or ring's share of chi-square (1 expected), and the excess
    #: kurtosis and realizations' share of it that its bounds take (table_noise.chi2_bounds)
    terms: np.ndarray
    kurtosis: np.ndarray
    common: np.ndarray
    quadrature_change: float  # rings: the largest last-refinement change, in standard errors
    notes: dict  # keys added to as_dict
    #: points of a table with their covariance: each incidence's Hotelling test (None where it has
    #: none: no point with spread, or as many as realizations or more); None: a table without it
    hotelling: list | None = None
    realizations: int = 0  # the realizations the points' errors come from

    def _exact_agree(self, i: int | None = None) -> bool:
        """Whether every exact point (of incidence ``i``, or of all) equals the model to EXACT_POINT."""
        rows = slice(None) if i is None else slice(i, i + 1)
        return not np.any(np.abs(self.z[rows][self.exact[rows]]) > 1.0)

    def metrics(self, i: int | None = None) -> dict:
        """The metrics of one incidence, or over all incidences (``i=None``)."""
        rows = slice(None) if i is None else slice(i, i + 1)
        m, s, ok, exact = self.model[rows], self.sim[rows], self.judged[rows], self.exact[rows]
        seen = ok & (s > 0)  # a relative error where the table has light
        rel = (m[seen] - s[seen]) / s[seen]
        z = self.z[rows][ok]
        noisy = ok & ~exact
        # without a point with spread there is no chi-square (None, as its bounds): the exact
        # points' agreement is the whole verdict
        chi2 = float(np.mean(self.terms[rows][noisy])) if noisy.any() else None
        bounds = list(chi2_bounds(self.kurtosis[rows][noisy], self.common[rows][noisy])) if noisy.any() else None
        agree = self._exact_agree(i)
        out = {
            self.counted: int(ok.sum()),
            "median_abs_rel_err": float(np.median(np.abs(rel))) if rel.size else float("nan"),
            "rel_rmse": float(np.sqrt(np.mean(rel**2))) if rel.size else float("nan"),
            "max_abs_z": float(np.max(np.abs(z))) if z.size else float("nan"),
            f"chi2_per_{self.unit}": chi2,
            "chi2_expected": 1.0,
            "chi2_bounds": bounds,
            # None where nothing is judged
            "consistent": bool(agree and (not noisy.any() or bounds[0] <= chi2 <= bounds[1])) if ok.any() else None,
        }
        out.update(self.more_metrics(i, exact, ok.any(), agree))
        if i is not None:
            out = {"theta_i_deg": config_degrees(self.theta_i[i]), "phi_i_deg": config_degrees(self.phi_i[i]), **out}
        return out

    def more_metrics(self, i: int | None, exact: np.ndarray, judged_any: bool, agree: bool) -> dict:
        """The judge's own keys of one incidence's (or all incidences') metrics, over the common
        ones; ``exact``: the exact points of those rows, ``agree``: whether they equal the model."""
        return {}

    def rules(self) -> dict:
        """The JSON keys that say how the values were judged."""
        raise NotImplementedError

    def summary(self) -> str:
        """One sentence of what was judged and by which statistic, for the CLI's report."""
        raise NotImplementedError

    def as_dict(self) -> dict:
        return {
            "model": self.model_name,
            "params": self.params,
            "order": self.order,
            "on": self.on,
            "per_incidence": [self.metrics(i) for i in range(len(self.theta_i))],
            "overall": self.metrics(),
            **self.rules(),
            **self.notes,
        }


def judged_values(table, model, order: str, judge, params: dict):
    """(the model made with ``params``, the table's values ``judge`` compares of ``order``, their
    standard errors), checked (ValueError, one line): the values present and finite, and the
    model not a tabulated one, whose errors are propagated to cells only."""
    from microsim.models import as_model

    model = as_model(model, **params)
    if getattr(model, "name", None) == "table":
        raise ValueError(f"--{judge.on} with --model table: the tabulated BRDF's errors are propagated to cells "
                         "only (compare the cells, or the two tables' points as tables of their own)")
    return (model, *extra_selection(table, order, judge))
