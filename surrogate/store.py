"""The Parquet stores: finished solves on disk, never lost, each file written atomically.

Two folders, one way of writing: :class:`SolveStore` keeps the full solves of the
identification's engine (a row per solve, keyed by its request), :class:`CampaignStore` the
tasks of a campaign (a row per solve, a part file per task). Their rows share the columns of
:mod:`surrogate.rows` (the tensor, the RVE's identity).

Layout of a campaign folder::

    campaign.json            the campaign (its checked form) and its fingerprint
    parts/<task>.parquet     one file per finished task: a row per solve
    rves/<rve_id>.parquet    the particle table of every RVE (re-solve any row from it)
    failures/<task>.json     the error of a task that failed (removed when it succeeds)

Every file is written to a temporary name in its folder and renamed when complete
(:func:`itr_fv.io.atomic_path`), so a run killed at any moment (SIGKILL included) leaves
only whole files: at most the tasks in flight are lost. A task whose part file exists is
done; a re-run skips it. A folder holds one campaign: running another into it is refused.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv
import pyarrow.parquet as pq

from itr_fv.io import atomic_path, write_text

from .campaign import Campaign, CampaignError
from .requests import SolveRequest, SolveResult, solve_row
from .rows import rve_id, tensor_columns, tensor_of

__all__ = ["CampaignStore", "CampaignStatus", "SolveStore", "RESULT_KEY", "rve_id",
           "tensor_columns", "tensor_of"]

#: Columns that identify a row (one solve) of a campaign.
RESULT_KEY = ("formulation", "replica", "set_index")


@dataclass(frozen=True)
class CampaignStatus:
    """Progress of a campaign folder."""

    name: str
    tasks_done: int
    tasks_total: int
    solves_done: int
    solves_total: int
    failures: dict[str, str]

    @property
    def complete(self) -> bool:
        return self.tasks_done == self.tasks_total

    def summary(self) -> str:
        lines = [f"campaign {self.name}: {self.tasks_done}/{self.tasks_total} tasks done, "
                 f"{self.solves_done}/{self.solves_total} solves"]
        lines += [f"  failed {task}: {message}" for task, message in self.failures.items()]
        return "\n".join(lines)


class CampaignStore:
    """The folder of one campaign.

    Parameters
    ----------
    folder : path
        The campaign folder; made absolute at once (in this process's working directory),
        so that a later change of directory moves nothing, and messages name it as given.
    """

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).absolute()
        self._shown = str(folder)

    # ------------------------------------------------------------------ campaign
    @property
    def campaign_file(self) -> Path:
        return self.folder / "campaign.json"

    def check_for(self, campaign: Campaign) -> bool:
        """Whether the folder already holds ``campaign`` (False: new or empty); writes nothing.

        Raises
        ------
        CampaignError
            If the folder holds another campaign (a different fingerprint) or files that
            are not a campaign's.
        """
        if self.campaign_file.exists():
            held = json.loads(self.campaign_file.read_text())
            if held.get("fingerprint") != campaign.fingerprint():
                raise CampaignError(f"--out: {self._shown!r} holds another campaign "
                                    f"({held.get('campaign', {}).get('name')!r}); use a new "
                                    "folder")
            return True
        if self.folder.exists() and any(self.folder.iterdir()):
            raise CampaignError(f"--out: {self._shown!r} is not empty and holds no "
                                "campaign; use a new folder")
        return False

    def open_for(self, campaign: Campaign) -> None:
        """Make the folder hold ``campaign``: new, or the same campaign again (see
        :meth:`check_for` for what is refused)."""
        if self.check_for(campaign):
            return
        from itr_fv import __version__

        self.folder.mkdir(parents=True, exist_ok=True)
        write_text(self.campaign_file, json.dumps(
            {"fingerprint": campaign.fingerprint(), "package_version": __version__,
             "campaign": campaign.to_dict()}, indent=2) + "\n")

    def campaign(self) -> Campaign:
        """The campaign this folder holds."""
        if not self.campaign_file.exists():
            raise CampaignError(f"{self._shown!r} holds no campaign (no campaign.json)")
        return Campaign.from_dict(json.loads(self.campaign_file.read_text())["campaign"])

    # --------------------------------------------------------------------- parts
    def part_path(self, task_id: str) -> Path:
        return self.folder / "parts" / f"{task_id}.parquet"

    def done_tasks(self) -> set[str]:
        """Tasks whose part file exists (temporary files of unfinished writes do not count)."""
        parts = self.folder / "parts"
        if not parts.is_dir():
            return set()
        return {p.stem for p in parts.glob("*.parquet") if not p.name.startswith(".")}

    def remove_partial_files(self) -> int:
        """Delete the temporary files that a killed run left behind; returns their number.

        Call only when no other run writes into this folder.
        """
        count = 0
        for sub in ("parts", "rves", "failures"):
            for p in (self.folder / sub).glob(".itr-partial-*"):
                p.unlink(missing_ok=True)
                count += 1
        return count

    def write_part(self, task_id: str, rows: list[dict]) -> Path:
        """Write one task's rows (atomically) and clear its failure record."""
        table = pa.Table.from_pylist(rows)
        with atomic_path(self.part_path(task_id)) as tmp:
            pq.write_table(table, tmp)
        (self.folder / "failures" / f"{task_id}.json").unlink(missing_ok=True)
        return self.part_path(task_id)

    def write_rve(self, rid: str, centers_m: np.ndarray, radii_m: np.ndarray,
                  materials: list[str], meta: dict) -> Path:
        """Store an RVE's particle table once (metadata: box, voxel, seed, formulation)."""
        path = self.folder / "rves" / f"{rid}.parquet"
        if path.exists():
            return path
        table = pa.table({"x_m": centers_m[:, 0], "y_m": centers_m[:, 1],
                          "z_m": centers_m[:, 2], "radius_m": radii_m,
                          "material": materials})
        table = table.replace_schema_metadata({"itr": json.dumps(meta)})
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp)
        return path

    def read_rve(self, rid: str) -> tuple[pa.Table, dict]:
        """Particle table and metadata of a stored RVE."""
        table = pq.read_table(self.folder / "rves" / f"{rid}.parquet")
        return table, json.loads(table.schema.metadata[b"itr"])

    def record_failure(self, task_id: str, message: str) -> None:
        write_text(self.folder / "failures" / f"{task_id}.json",
                   json.dumps({"task": task_id, "error": message}) + "\n")

    def failures(self) -> dict[str, str]:
        folder = self.folder / "failures"
        if not folder.is_dir():
            return {}
        return {p.stem: json.loads(p.read_text())["error"] for p in sorted(folder.glob("*.json"))}

    # ------------------------------------------------------------------ results
    def results(self) -> pa.Table:
        """All finished rows, sorted by formulation, replica and parameter set."""
        files = [self.part_path(t) for t in sorted(self.done_tasks())]
        if not files:
            raise CampaignError(f"{self._shown!r} has no finished solve yet")
        table = pa.concat_tables([pq.read_table(f) for f in files], promote_options="default")
        return table.sort_by([(k, "ascending") for k in RESULT_KEY])

    def export_csv(self, path: str | Path) -> int:
        """All finished rows as one CSV file (written atomically); returns the row count."""
        table = self.results()
        with atomic_path(path) as tmp:
            pa.csv.write_csv(table, tmp)
        return table.num_rows

    def status(self) -> CampaignStatus:
        camp = self.campaign()
        tasks = camp.tasks()
        done = self.done_tasks()
        solves_done = sum(len(t.set_indices) for t in tasks if t.task_id in done)
        return CampaignStatus(camp.name, len(done & {t.task_id for t in tasks}), len(tasks),
                              solves_done, camp.n_solves(),
                              {k: v for k, v in self.failures().items() if k not in done})


class SolveStore:
    """Finished solves in a folder: ``solves/<key>.parquet`` (one row each) and
    ``fields/<key>.npz`` (theta, where asked for), each written atomically, by the client
    (``folder`` is made absolute at once)."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).absolute()

    def _row_path(self, key: str) -> Path:
        return self.folder / "solves" / f"{key}.parquet"

    def _field_path(self, key: str) -> Path:
        return self.folder / "fields" / f"{key}.npz"

    def get(self, request: SolveRequest) -> SolveResult | None:
        """The stored result of ``request`` (None if not finished, or fields missing)."""
        key = request.key
        path = self._row_path(key)
        if not path.is_file():
            return None
        theta = None
        if request.fields:
            fpath = self._field_path(key)
            if not fpath.is_file():
                return None
            with np.load(fpath, allow_pickle=False) as data:
                theta = data["theta"]
        row = pq.read_table(path).to_pylist()[0]
        k = tensor_of(row)
        ke = np.array(json.loads(row["k_energy_json"]))
        return SolveResult(k, ke, json.loads(row["iterations_json"]), row["residual"],
                           row["wall_s"], theta, True, False)

    def put(self, request: SolveRequest, result: SolveResult) -> None:
        """Write one finished solve (fields first, so a row always has its fields)."""
        key = request.key
        if request.fields and result.theta is not None:
            self._field_path(key).parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(self._field_path(key)) as tmp, open(tmp, "wb") as fh:
                np.savez(fh, theta=result.theta)
        row = solve_row(request, result)
        path = self._row_path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            pq.write_table(pa.Table.from_pylist([row]), tmp)

    def _rows(self) -> list[Path]:
        folder = self.folder / "solves"
        if not folder.is_dir():
            return []
        # partial files of a killed write start with a dot (itr_fv.io.atomic_path)
        return sorted(p for p in folder.glob("*.parquet") if not p.name.startswith("."))

    def count(self) -> int:
        """Finished solves in the store."""
        return len(self._rows())

    def _fields(self) -> list[Path]:
        folder = self.folder / "fields"
        return sorted(folder.glob("*.npz")) if folder.is_dir() else []

    def field_count(self) -> tuple[int, int]:
        """(number, bytes) of the stored fields."""
        files = self._fields()
        return len(files), sum(f.stat().st_size for f in files)

    def drop_fields(self) -> tuple[int, int]:
        """Remove every stored field (the rows stay: a request that keeps fields is then
        solved again, one that does not is still answered); returns (number, bytes)."""
        n, size = self.field_count()
        for f in self._fields():
            f.unlink(missing_ok=True)
        return n, size

    def table(self) -> pa.Table:
        """Every stored solve as one table (columns of all rows)."""
        files = self._rows()
        if not files:
            return pa.table({})
        return pa.concat_tables([pq.read_table(f) for f in files], promote_options="default")
