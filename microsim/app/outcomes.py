"""What a run tells when it ends: a finished run, a sweep's point and a sweep, with the lines
``microsim run`` prints (the albedos, the time and rate, and the notes: compiling, paths rounded
up, energy lost beyond the albedo's error, the backend's substitutions)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from microsim.core.orders import RESULT_ALL_ORDERS

#: compiling shorter than this is not worth a line of the report
COMPILE_NOTE_SECONDS = 0.5
#: why energy leaves a run without reaching the sensor, by energy/ dataset
ENERGY_CAUSES = {"transmitted": "left through the bottom of the scene (a deeper scene, or a base, keeps it)",
                 "truncated": "cut when paths reached run.max_order or the tracer's limit of interactions"}


@dataclass
class RunOutcome:
    """A finished run: its plan, its tables (one per albedo), its results (``microsim.run.reduction.Result``,
    in the tables' order) and the seconds numba spent compiling before it traced."""

    config: object
    plan: object
    tables: list[Path]
    results: list
    compiling: float
    options: object  # the run's microsim.app.session.Options

    @property
    def paths_per_second(self) -> float:
        """Paths traced (not resumed) per second of tracing; NaN where nothing was traced."""
        first = self.results[0]
        traced = self.plan.paths * self.plan.n_incidences * first.units_traced / len(self.plan.units)
        return traced / first.wall_time if traced and first.wall_time > 0 else math.nan

    def albedo_summary(self, result) -> str:
        """The albedo of every incidence with its standard error, named by theta_i (and phi_i
        where the incidences pair their azimuths)."""
        plan = self.plan
        azimuths = len(set(plan.phi_i.tolist())) > 1
        return ", ".join(
            f"{math.degrees(t):g}{f'/{math.degrees(p):g}' if azimuths else ''}deg "
            f"{a.mean[RESULT_ALL_ORDERS]:.4f}+-{a.stderr[RESULT_ALL_ORDERS]:.4f}"
            for t, p, a in zip(plan.theta_i, plan.phi_i, result.albedo))

    def report(self) -> list[str]:
        """The lines ``microsim run`` prints: the albedos, the time and rate, the backend and the
        scene's intersector, and the notes (compiling, paths rounded up, energy lost beyond the
        albedo's error, the backend's substitutions), then where the tables went."""
        plan, results, first = self.plan, self.results, self.results[0]
        summaries = [self.albedo_summary(result) for result in results]
        rate = f"{self.paths_per_second:.3g} paths/s, " if first.units_traced else ""
        timing = f"{first.wall_time:.1f} s, {rate}{self.options.where(plan)}, backend {plan.backend}"
        if plan.scene.get("intersector"):
            timing += f", intersector {plan.scene['intersector']}"
        if first.units_resumed:
            timing += f"; {first.units_resumed} of {len(plan.units)} units resumed, {first.units_traced} traced"
        if len(results) == 1:
            lines = [f"albedo {summaries[0]} | {timing}"]
        else:
            lines = [f"material albedo {result.albedo_value:g}: albedo {summary} -> {path}"
                     for path, result, summary in zip(self.tables, results, summaries)]
            lines.append(f"{len(results)} albedos from one run of {plan.paths:,} paths an incidence: {timing}")
        lines += self.notes()
        lines.append(f"table written to {self.tables[0]}" if len(self.tables) == 1 else
                     f"{len(self.tables)} tables written")
        return lines

    def notes(self) -> list[str]:
        """The lines after a run's albedos (see :meth:`report`)."""
        config, plan, notes = self.config, self.plan, []
        if self.compiling >= COMPILE_NOTE_SECONDS:
            notes.append(f"compiled the tracer in {self.compiling:.1f} s (not in the time above; once for this "
                         "machine and these sources, then loaded from numba's cache)")
        if plan.paths != config.run.paths:
            notes.append(f"paths: {plan.paths:,} an incidence traced for the {config.run.paths:,} asked: "
                         f"{plan.realizations} realizations of {plan.paths_per_realization:,} (run.paths rounded up "
                         "to a multiple of run.realizations)")
        for result in self.results:
            notes.extend(energy_notes(plan, result))
        if plan.backend_note:
            notes.append(f"note: {plan.backend_note}")
        from microsim.geometry.periodic_tile import steepness_note

        if (steep := steepness_note(plan.scene)) and self.results[0].units_traced:
            notes.append(f"note: {steep}: {self.paths_per_second:.3g} paths/s here")
        return notes


@dataclass
class PointOutcome:
    """One point of a sweep: its table and its albedos; ``summary`` and ``wall_time`` of its run
    ("" and 0 where ``resume`` kept its table). The tables hold the rest: a sweep keeps no
    point's estimates in memory."""

    point: object  # microsim.app.sweep.Point
    table: Path
    albedo: list[float]  # per incidence, all orders
    summary: str = ""
    wall_time: float = 0.0

    @property
    def kept(self) -> bool:
        return not self.summary

    def line(self) -> str:
        """What ``microsim run`` prints as the point ends."""
        if self.kept:
            return f"{self.point.name}: kept (its table was finished)"
        return f"{self.point.name}: albedo {self.summary} | {self.wall_time:.1f} s"


@dataclass
class SweepOutcome:
    """A finished sweep: its directory, its points in order, and its index."""

    directory: Path
    points: list[PointOutcome] = field(default_factory=list)

    @property
    def index(self) -> Path:
        """The sweep's index.csv."""
        from microsim.app import sweep

        return self.directory / sweep.INDEX

    def report(self) -> list[str]:
        """The line ``microsim run`` prints once the sweep is done."""
        from microsim.app import sweep

        return [f"{len(self.points)} tables and {sweep.INDEX} written to {self.directory}"]


def energy_notes(plan, result) -> list[str]:
    """One line for each kind of lost energy (transmitted, truncated) that exceeds the albedo's
    standard error at some incidence: there the albedo is short of the scene's by more than
    its noise (the table's energy/ datasets hold every incidence)."""
    from microsim.core.tally import ENERGY_NAMES

    lines = []
    for name, cause in ENERGY_CAUSES.items():
        j = ENERGY_NAMES.index(name)
        lost = [(t, energy.mean[j]) for t, energy, albedo in zip(plan.theta_i, result.energy, result.albedo)
                if energy.mean[j] > albedo.stderr[RESULT_ALL_ORDERS]]
        if lost:
            where = ", ".join(f"{math.degrees(t):g}deg {value:.4f}" for t, value in lost)
            albedo = f"material albedo {result.albedo_value:g}: " if result.albedo_value is not None else ""
            lines.append(f"{albedo}energy {name}, beyond the albedo's standard error: {where} ({cause})")
    return lines
