"""Finished units of a run kept on disk, so that a run stopped by a crash, ``kill -9`` or a signal
resumes where it stopped (``microsim run --resume``, docs/conventions.md §7).

A run's units (realization x incidence, :attr:`microsim.run.plan.Plan.units`) are saved one file
each, as they end, in the directory ``<table>.partial`` beside the table: the unit's tally
(:class:`~microsim.core.tally.Tally`: each estimator's fields, arrays stored exactly in ``.npz``) and its
realization's scene info (JSON). Each file is written under a temporary name, flushed to disk
and renamed, so a kill or a crash of the machine leaves whole units only; a file that does not
read back whole is dropped when the store opens, and its unit is traced again.

The directory's ``manifest.json`` holds the run's fingerprint: the validated config, the
backend it resolved to, and the stamps of microsim's and the generators' sources
(:func:`microsim.tracer.jit.kernel_cache.package_stamp`); unit files carry the fingerprint's key in their
names. Units are only taken from a store of the same fingerprint, and the table reduced from
saved and new units is bit-identical to an uninterrupted run's because the reduction sums
tallies in unit order whatever their origin. A run holds an exclusive lock on its store
(``flock``): a second run with the same ``--out`` is refused instead of sharing it. The
directory is removed once the table is written.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import zipfile
from pathlib import Path

import numpy as np

from microsim import __version__
from microsim.core.tally import Tally
from microsim.tracer import estimators
from microsim.tracer.jit import kernel_cache

MANIFEST = "manifest.json"
SUFFIX = ".partial"
#: the arrays of a unit file, besides the fields of each estimator (named "<estimator>.<field>")
FIELDS = ("paths", "energy", "counts", "albedo_scale", "info")


class StoreMismatch(ValueError):
    """The store cannot be used as asked; the message is one line saying why."""


class UnitNotSaved(OSError):
    """A finished unit could not be written to the store (a full disk, say); one line naming the
    file, the reason and the space left. Nothing of it is left behind."""


def store_path(table: Path) -> Path:
    """Where the units of the run writing ``table`` are kept."""
    return table.with_name(table.name + SUFFIX)


def fingerprint(plan) -> dict:
    """What a saved unit depends on: the config, the backend traced, the sources that trace it."""
    return {
        "config": plan.config.model_dump(mode="json", exclude_none=True),
        "backend": plan.backend,
        "estimators": list(plan.estimator_names),
        "microsim_version": __version__,
        # what a unit's numbers depend on: the tracer's sources, and the contract, config and run
        # that make its incidences, sensor and paths
        "sources": "".join(kernel_cache.package_stamp(root).hex()
                           for root in (*kernel_cache.tracer_sources(),
                                        *(kernel_cache.PACKAGE / name for name in ("core", "config", "run")))),
    }


def _digest(print_: dict) -> str:
    return hashlib.sha256(json.dumps(print_, sort_keys=True).encode()).hexdigest()


class UnitStore:
    """The units saved for one run. :meth:`check` says whether a run may use the directory;
    :meth:`take` then takes it (locked) for the run; :meth:`open` is the two at once."""

    def __init__(self, directory: Path, print_: dict, records: dict | None = None):
        """``records``: the Record class of each estimator of the run, by name (microsim.tracer.estimators)."""
        self.directory = Path(directory)
        self.fingerprint = print_
        self.key = _digest(print_)
        self.records = records or {}
        self.fields = FIELDS + tuple(f"{name}.{field}" for name, record in self.records.items() for field in record._fields)
        self._lock = None
        self.resume = self.force = False

    @classmethod
    def check(cls, directory: Path, plan, resume: bool, force: bool = False) -> "UnitStore":
        """The store at ``directory`` for ``plan``, if a run may take it; writes nothing.

        Without ``resume`` the directory must hold no finished unit (StoreMismatch: nothing is
        discarded unasked) unless ``force``; with it, its units must come from the same
        fingerprint (StoreMismatch naming what changed)."""
        store = cls(directory, fingerprint(plan), {name: estimators.get(name).Record for name in plan.estimator_names})
        store.resume, store.force = resume, force
        store._verify()
        return store

    def _verify(self) -> None:
        """StoreMismatch (one line) unless the run may take the directory as it is now (:meth:`check`)."""
        directory, resume, force = self.directory, self.resume, self.force
        if not directory.exists() or (force and not resume):
            return
        if not directory.is_dir():
            raise StoreMismatch(f"{directory} is not a directory of units; remove it, or pass --force")
        try:
            theirs = json.loads((directory / MANIFEST).read_text())
        except (OSError, ValueError):
            theirs = None
        units = len(list(directory.glob("r*_i*.npz")))
        if units and not resume:
            raise StoreMismatch(f"{directory} holds {units} finished units of an interrupted run: pass --resume to "
                                "continue it, or --force to discard them")
        if units and (not isinstance(theirs, dict) or _digest(theirs) != self.key):
            why = (_difference(theirs, self.fingerprint) if isinstance(theirs, dict)
                   else f"its {MANIFEST} is missing or damaged")
            discard = "pass --force without --resume" if force else "pass --force"
            raise StoreMismatch(f"--resume: {directory} holds units of another run ({why}); rerun with the config "
                                f"they came from, or {discard} to discard them")

    @classmethod
    def open(cls, directory: Path, plan, resume: bool, force: bool = False) -> "UnitStore":
        """:meth:`check`, then :meth:`take`."""
        return cls.check(directory, plan, resume, force).take()

    def take(self) -> "UnitStore":
        """Take the directory for the run this store was checked for: lock it (StoreMismatch if
        another run holds it), drop unit files that do not read back whole, and start it afresh
        (with this run's manifest) unless it holds this run's units."""
        if self.directory.exists() and not self.directory.is_dir():
            self._verify()  # a file in its place goes with --force only, as check said, and as it is now
            self.directory.unlink()
        self.directory.mkdir(parents=True, exist_ok=True)
        descriptor = os.open(self.directory, os.O_RDONLY)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(descriptor)
            raise StoreMismatch(f"{self.directory} is in use by another run writing the same table; wait for it to end, "
                                "or give this one another --out") from None
        self._lock = descriptor
        try:  # what another run left meanwhile (it held the lock), seen now that this one holds it
            self._verify()
        except StoreMismatch:
            self.release()
            raise
        for stray in self.directory.glob(".*.tmp"):  # a write a kill cut short
            stray.unlink()
        if not (self.resume and self._drop_damaged()):
            for path in self.directory.iterdir():
                shutil.rmtree(path) if path.is_dir() else path.unlink()
            _write_durably(self.directory / MANIFEST, json.dumps(self.fingerprint, sort_keys=True).encode())
        return self

    def _unit_file(self, unit) -> Path:
        return self.directory / f"r{unit[0]}_i{unit[1]}.{self.key[:16]}.npz"

    def _drop_damaged(self) -> int:
        """Remove unit files of this store that do not open whole; the number of good ones."""
        good = 0
        for path in self.directory.glob(f"r*_i*.{self.key[:16]}.npz"):
            try:
                with zipfile.ZipFile(path) as archive:
                    whole = {name.removesuffix(".npy") for name in archive.namelist()} == set(self.fields) and \
                        archive.testzip() is None
            except (OSError, zipfile.BadZipFile, EOFError, ValueError):
                whole = False
            if whole:
                good += 1
            else:
                path.unlink()
        return good

    def saved_units(self) -> list[tuple[int, int]]:
        """Units of this run with a file in the store."""
        if not self.directory.is_dir():
            return []
        units = []
        for path in self.directory.glob(f"r*_i*.{self.key[:16]}.npz"):
            r, _, i = path.name.split(".")[0][1:].partition("_i")
            if r.isdigit() and i.isdigit():
                units.append((int(r), int(i)))
        return sorted(units)

    def save(self, unit, tally: Tally, info: dict) -> None:
        """Keep a finished unit (durably and atomically: a crash leaves the whole file or none)."""
        path = self._unit_file(unit)
        tmp = path.with_name(f".{path.name}.tmp")
        try:
            with open(tmp, "wb") as handle:
                fields = {f"{name}.{field}": values for name, record in zip(self.records, tally.estimates)
                          for field, values in record._asdict().items()}
                np.savez(handle, paths=np.int64(tally.paths), energy=tally.energy, counts=tally.counts,
                         albedo_scale=tally.albedo_scale, info=np.frombuffer(json.dumps(_plain(info)).encode(), np.uint8),
                         **fields)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, path)
        except OSError as err:
            tmp.unlink(missing_ok=True)
            try:
                free = f", {shutil.disk_usage(self.directory).free / 1e6:.1f} MB free there"
            except OSError:
                free = ""
            raise UnitNotSaved(f"cannot save unit {path.name} in {self.directory}: {err.strerror or err}{free}") from None

    def load(self, unit) -> tuple[Tally, dict]:
        """A saved unit's tally and scene info, as they were saved."""
        with np.load(self._unit_file(unit), allow_pickle=False) as data:
            records = tuple(record._make(data[f"{name}.{field}"] for field in record._fields)
                            for name, record in self.records.items())
            tally = Tally(int(data["paths"]), 0, records, data["energy"], data["counts"], data["albedo_scale"])
            info = json.loads(data["info"].tobytes().decode())
        return tally, info

    def clear(self) -> None:
        """Remove the store and its units, and let it go."""
        if self.directory.is_dir():
            shutil.rmtree(self.directory)
        elif self.directory.exists():
            self.directory.unlink()
        self.release()

    def release(self) -> None:
        """Let another run take the store (the lock also goes with this process)."""
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None


#: the dtypes of scene-info arrays, which JSON gives back as they were (np.array of the lists)
INFO_DTYPES = (np.float64, np.int64, np.bool_)


def _plain(info: dict) -> dict:
    """Scene info with numpy scalars and arrays as Python numbers and lists (JSON keeps a float's
    every bit). An array of another dtype than INFO_DTYPES would come back as another one (a
    resumed table would differ from a fresh one): a TypeError."""
    for key, value in info.items():
        if isinstance(value, np.ndarray) and value.dtype.type not in INFO_DTYPES:
            raise TypeError(f"scene info {key!r}: an array of {value.dtype}; give one of {INFO_DTYPES}")
    return {k: (v.item() if isinstance(v, np.generic) else v.tolist() if isinstance(v, np.ndarray) else v)
            for k, v in info.items()}


def _write_durably(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def _difference(saved: dict, now: dict) -> str:
    """The first few keys whose values differ between two fingerprints, as one phrase."""
    flat_saved, flat_now = _flatten(saved), _flatten(now)
    keys = [k for k in dict.fromkeys([*flat_saved, *flat_now]) if flat_saved.get(k) != flat_now.get(k)]
    if keys == ["sources"]:
        return "microsim's sources changed since they were traced"
    shown = [f"{k.removeprefix('config.')}: {flat_saved.get(k, 'unset')} -> {flat_now.get(k, 'unset')}"
             for k in keys if k != "sources"][:3]
    return "; ".join(shown) + ("; ..." if len(keys) > 3 else "")


def _flatten(data: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in data.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat
