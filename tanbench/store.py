"""The results directory: Parquet files written atomically, with provenance.

Layout of ``DIR``::

    sweep.yaml                                 the sweep that wrote it (tables are built from it)
    runs/cell_id=<id>/run-<r>.parquet          one file per finished task: a row per method ...
    runs/cell_id=<id>/runs.parquet             ... merged into one file per cell when a session ends
    series/summary.parquet                     Monte Carlo mean and percentiles over time
    series/runs/cell_id=<id>/run-<r>.parquet   every run's series (--series full)
    .work/series/cell_id=<id>/...              the same, kept out of sight (--series summary)
    tables/<table>.parquet, .md                the paper-style summary tables

``runs/`` and ``series/runs/`` are Hive-partitioned by ``cell_id``: the files hold every
other column (one fixed schema) and the directory name holds the cell, so
``pd.read_parquet(DIR / "runs")`` reads them all with a ``cell_id`` column.

Every file is written to a temporary name in its directory (``.<name>.<pid>.tmp``) and
renamed into place, so an interrupted sweep never leaves a half-written file under its
real name; a sweep deletes the temporaries a killed one left (``remove_stale_temporaries``).
Every Parquet file carries the provenance (sweep YAML, root seed, versions, git
revision, creation time) and the schema version in its schema metadata under the key
``tanbench``.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import subprocess
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from tanbench.errors import TanbenchError
from tanbench import __version__
from tanbench.schema import rows_table, run_schema

SCHEMA_VERSION = 3  # 3: Hive-partitioned runs/cell_id=<id>/, one fixed run-file schema, merged cells
META_KEY = b"tanbench"


@lru_cache(maxsize=1)
def git_revision() -> str:
    """The checkout's short revision ("-dirty" with uncommitted changes outside results/), "" outside a
    git checkout."""
    root = Path(__file__).resolve().parents[1]  # the project root (this file is tanbench/store.py)
    try:
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=5)
        rev = out.stdout.strip()
        if rev:
            # the code's changes only: a make target rewriting the committed results/ is not one
            dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "--",
                                    ".", ":(exclude)results"], capture_output=True, text=True, timeout=5).stdout.strip()
            return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return ""


def provenance(sweep_text: str, sweep_name: str, root_seed: int) -> dict:
    """What produced a result file: the sweep, its seed and the software versions."""
    import numba
    import numpy


    return {
        "schema_version": SCHEMA_VERSION,
        "sweep": sweep_name,
        "sweep_yaml": sweep_text,
        "root_seed": root_seed,
        "tanbench_version": __version__,
        "git_revision": git_revision(),
        "numpy_version": numpy.__version__,
        "numba_version": numba.__version__,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }


def write_parquet(df: pd.DataFrame, path: Path, meta: dict) -> None:
    """Write ``df`` to ``path`` atomically with ``meta`` in the schema metadata."""
    write_table(pa.Table.from_pandas(df, preserve_index=False), path, meta)


# how a finished task's files are encoded (``write_table(..., **TASK_ROWS)`` / ``TASK_SERIES``): a task's
# run rows (3 rows of ~180 columns) uncompressed and a task's series without dictionaries, which
# on such files cost more than they save (the CI-size sweep's task files: rows 9 -> 3.3 ms each,
# 31 -> 26 kB; series 7 -> 2.9 ms, 314 -> 210 kB). The values read back are the same.
TASK_ROWS = {"compression": "none", "dictionary": False}
TASK_SERIES = {"compression": "zstd", "dictionary": False}


def write_table(table: pa.Table, path: Path, meta: dict, compression: str = "zstd", dictionary: bool = True) -> None:
    """Write an Arrow ``table`` to ``path`` atomically with ``meta`` in the file's key-value metadata.

    The footer holds tanbench's metadata once: no pandas metadata (our frames have no index
    or pandas-only types), no serialised Arrow schema (which would repeat the metadata;
    our columns are plain numbers, booleans and strings, which Parquet's own types bring
    back exactly) and no column statistics (results are read whole). A 60-row cell's file
    is then about a third of its former size, most of which was footer. ``compression`` and
    ``dictionary`` (Parquet's dictionary encoding) change the bytes, never the values read back.
    """
    table = table.replace_schema_metadata(None)

    def write(fh):
        with pq.ParquetWriter(fh, table.schema, compression=compression, use_dictionary=dictionary,
                              write_statistics=False, store_schema=False) as writer:
            writer.write_table(table)
            writer.add_key_value_metadata({META_KEY: json.dumps(meta).encode()})

    _write_atomically(path, write)


def is_compact_format(path: Path) -> bool:
    """True if ``path`` was written by :func:`write_table` as it is now (footer with our metadata only)."""
    return set(pq.read_metadata(path).metadata or {}) == {META_KEY}


def write_text(text: str, path: Path) -> None:
    """Write a text file atomically."""
    _write_atomically(path, lambda fh: fh.write(text.encode()))


def _write_atomically(path: Path, write) -> None:
    """``write(binary file)`` into a temporary ``.<name>.<pid>.tmp``, synced, then renamed to ``path``.

    A write that fails (a full disk, a file system that refuses the name) leaves no
    temporary behind and is one :class:`TanbenchError` line naming the path."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        raise TanbenchError(f"cannot write {path}: {exc.strerror or exc} (what was stored before is kept; "
                            f"fix this and rerun to resume)") from None


def read_meta(path: Path) -> dict:
    """The tanbench metadata of one Parquet file; a clear error if it is not one of ours."""
    try:
        schema = pq.read_schema(path)
    except (OSError, pa.ArrowException) as exc:
        raise TanbenchError(f"{path}: not a readable Parquet file ({_first_line(exc)}); {RECOVERY}") from None
    return _checked_meta(path, schema.metadata)


RECOVERY = ("`tanbench run` of the directory's sweep into it sets a damaged run or series file, or series summary, "
            "aside and recomputes what it held")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _checked_meta(path: Path, metadata) -> dict:
    """The tanbench metadata of a file's key-value ``metadata``, of this schema (one error line otherwise)."""
    raw = (metadata or {}).get(META_KEY)
    try:
        meta = json.loads(raw) if raw is not None else None
    except ValueError:
        meta = None
    if not isinstance(meta, dict):
        raise TanbenchError(f"{path}: not written by tanbench (no 'tanbench' metadata)")
    version = meta.get("schema_version")
    if version != SCHEMA_VERSION:
        # --force cannot help: it only replaces the current sweep's cells, not the others
        raise TanbenchError(
            f"{path}: written with results schema {version}, this tanbench reads schema {SCHEMA_VERSION}; "
            f"write to a new --out directory (or delete this one), or use the tanbench version that wrote it")
    return meta


def is_tanbench_file(path: Path) -> bool:
    """Whether ``path`` is a Parquet file written by tanbench (any schema version)."""
    try:
        return META_KEY in (pq.read_schema(path).metadata or {})
    except (OSError, pa.ArrowException):
        return False


def read_parquet(path: Path, columns=None) -> pd.DataFrame:
    """Read one of our Parquet files (checking its schema) into pandas."""
    read_meta(path)
    try:
        return pq.read_table(path, columns=columns).to_pandas()
    except (OSError, pa.ArrowException) as exc:
        raise TanbenchError(f"{path}: corrupt Parquet file ({_first_line(exc)}); {RECOVERY}") from None


PARTITION = "cell_id"


def cell_dir(base: Path, cell_id: str) -> Path:
    """The Hive partition directory of a cell under ``base``."""
    return base / f"{PARTITION}={cell_id}"


def cell_of(path: Path) -> str:
    """The cell id of a file in a Hive partition directory."""
    return path.parent.name.split("=", 1)[1]


def run_file(out: Path, cell_id: str, run: int) -> Path:
    return cell_dir(out / "runs", cell_id) / f"run-{run:05d}.parquet"


def series_dir(out: Path, full: bool) -> Path:
    """Where per-run series live: ``series/runs`` (--series full) or ``.work/series`` (summary)."""
    return out / "series" / "runs" if full else out / ".work" / "series"


def summary_file(out: Path) -> Path:
    """The series summary: the Monte Carlo statistics over time of every cell (``results.build_outputs``)."""
    return out / "series" / "summary.parquet"


def unreadable_summary(out: Path) -> str | None:
    """Why ``out``'s series summary cannot be read (its first line), or None (readable, or none there)."""
    path = summary_file(out)
    if not path.exists():
        return None
    try:
        pq.read_metadata(path)
    except (OSError, pa.ArrowException) as exc:
        return _first_line(exc)
    return None


def series_file(out: Path, cell_id: str, run: int, full: bool) -> Path:
    return cell_dir(series_dir(out, full), cell_id) / f"run-{run:05d}.parquet"


def run_files(out: Path) -> list[Path]:
    """Every stored runs file, per cell the merged ``runs.parquet`` first, then the per-task
    ``run-*.parquet`` written since (newer rows last, as :func:`compact_cells` merges them)."""
    files = [p for p in (out / "runs").glob(f"{PARTITION}=*/*.parquet") if not p.name.startswith(".")]
    return sorted(files, key=lambda p: (p.parent.name, p.name != "runs.parquet", p.name))


MERGED_RUNS = "runs.parquet"
# run-file metadata: the content hash of a file terrain's maps, and each user method's code identity
TERRAIN_META = "terrain_sha256"
CODE_META = "method_code"
IDENTITY_COLUMNS = ["run", "method", "seed", "filter_seed", "status", "sweep"]
RUN_INDEX_COLUMNS = ["cell_id", *IDENTITY_COLUMNS, "terrain", "code", "root_seed", "git_revision", "path", "mtime"]


def read_run_index(out: Path) -> tuple[pd.DataFrame, list[tuple[Path, str]]]:
    """One pass over every stored run file: the identity columns of its rows with what its
    metadata says of them, and the files that cannot be read.

    Columns: cell_id, the :data:`IDENTITY_COLUMNS`, ``terrain`` (the file's map hash or
    None), ``code`` (the method's code identity in the file, None if not recorded),
    ``root_seed``, ``git_revision`` (of the checkout that wrote the file, "" if unknown), ``path`` and ``mtime``. A row stored twice (a merged file and a task
    file written since) is kept once, the newer. A file of another schema or not written
    by tanbench is an error (:func:`read_meta`); an unreadable one is listed with why.
    """
    frames, damaged = [], []
    for path in run_files(out):
        try:
            parquet = pq.ParquetFile(path)
            meta = _checked_meta(path, parquet.metadata.metadata)
            table = parquet.read(columns=[c for c in IDENTITY_COLUMNS if c in parquet.schema_arrow.names])
        except (OSError, pa.ArrowException) as exc:
            damaged.append((path, _first_line(exc)))
            continue
        df = table.to_pandas()
        codes = meta.get(CODE_META) or {}
        df.insert(0, "cell_id", cell_of(path))
        df["terrain"] = meta.get(TERRAIN_META)
        df["code"] = df["method"].map(lambda m, codes=codes: codes.get(m))
        df["root_seed"] = meta.get("root_seed")
        df["git_revision"] = meta.get("git_revision") or ""
        df["path"] = str(path)
        df["mtime"] = path.stat().st_mtime
        frames.append(df)
    if not frames:
        return pd.DataFrame(columns=RUN_INDEX_COLUMNS), damaged
    rows = pd.concat(frames, ignore_index=True).reindex(columns=RUN_INDEX_COLUMNS)
    return rows.drop_duplicates(subset=["cell_id", "method", "run"], keep="last").reset_index(drop=True), damaged


def series_runs(out: Path, check: bool = False) -> tuple[set[tuple[str, int]], list[tuple[Path, str]]]:
    """(cell, run) of every stored per-run series file, in either series directory; with
    ``check``, only the readable ones, and the unreadable files with why."""
    found, damaged = set(), []
    for full in (False, True):
        for path in series_dir(out, full).glob(f"{PARTITION}=*/run-*.parquet"):
            if check:
                try:
                    pq.read_metadata(path)
                except (OSError, pa.ArrowException) as exc:
                    damaged.append((path, _first_line(exc)))
                    continue
            found.add((cell_of(path), int(path.stem.split("-", 1)[1])))
    return found, damaged


def set_aside(path: Path) -> Path:
    """Rename a damaged file to ``.<name>.damaged`` (a free name): hidden, so out of every
    reader's way (pyarrow's datasets skip names starting with a dot), kept for a look."""
    target = path.with_name(f".{path.name}.damaged")
    n = 1
    while target.exists():
        target = path.with_name(f".{path.name}.damaged.{n}")
        n += 1
    os.replace(path, target)
    return target


def compact_cells(out: Path, cell_ids, kept: dict | None = None) -> None:
    """Merge each cell's per-task files into one ``runs/cell_id=<id>/runs.parquet``.

    One file per finished task keeps a running sweep safe to kill; once a session ends,
    the cell's rows are gathered into one file (a results directory of 550 tasks then
    holds 11 files instead of 550, small enough to commit). The merged file is written
    atomically before the task files are deleted; if a kill falls in between, the rows
    exist twice and :func:`tanbench.results.load` keeps one copy. A merged file in an
    older footer format (:func:`is_compact_format`) is rewritten, rows unchanged.

    ``kept``: the task files this session wrote, by path, as (rows, metadata) (the engine's
    :class:`~tanbench.runner.engine.SeriesWritten`): their tables are built again from the rows
    (:func:`tanbench.schema.rows_table`, as they were written; consecutive files of one schema in
    one table) instead of being read back. Any other file is read.
    """
    kept = kept or {}
    for cell_id in cell_ids:
        directory = cell_dir(out / "runs", cell_id)
        parts = sorted(directory.glob("run-*.parquet"))
        merged_path = directory / MERGED_RUNS
        if not parts and (not merged_path.exists() or is_compact_format(merged_path)):
            continue
        sources = ([merged_path] if merged_path.exists() else []) + parts
        tables = _source_tables(sources, kept)
        metas = [kept[p][1] if p in kept else read_meta(p) for p in sources]
        meta = metas[-1]
        codes = {}
        for m in metas:  # each user method's code identity, as of the newest file that ran it
            codes.update(m.get(CODE_META) or {})
        if codes:
            meta = {**meta, CODE_META: codes}
        table = pa.concat_tables([t.replace_schema_metadata(None) for t in tables], promote_options="default")
        df = table.to_pandas().drop_duplicates(subset=["method", "run"], keep="last")
        df = df.sort_values(["run", "method"], kind="stable").reset_index(drop=True)
        # the sources' unified schema (the same as each one's when they agree): a file written before a
        # metric existed, merged after files that have it, reads as null there instead of dropping the column
        write_table(pa.Table.from_pandas(df, schema=table.schema, preserve_index=False), merged_path, meta)
        for p in parts:
            p.unlink(missing_ok=True)


def _source_tables(sources, kept: dict) -> list[pa.Table]:
    """The tables of ``sources`` in order: read from their files, or built from the rows ``kept``
    for them (one table for each run of consecutive kept files whose rows have one schema)."""
    tables, group, group_schema = [], [], None
    for path in sources:
        rows = kept[path][0] if path in kept else None
        schema = run_schema(rows) if rows is not None else None
        if group and (schema is None or schema != group_schema):
            tables.append(rows_table(group))
            group = []
        if rows is None:
            tables.append(pq.read_table(path))
        else:
            group, group_schema = group + rows, schema
    if group:
        tables.append(rows_table(group))
    return tables


def check_layout(out: Path) -> None:
    """Refuse Parquet files under ``runs/`` outside this layout (older tanbench versions):
    their metadata names the schema that wrote them, which is the clearest message."""
    ours = set(run_files(out))
    for path in sorted((out / "runs").rglob("*.parquet")):
        if path not in ours and not path.name.startswith("."):
            read_meta(path)
            raise TanbenchError(f"{path}: not in this tanbench's results layout (runs/cell_id=<id>/*.parquet); "
                                f"write to a new --out directory or delete this one")


def check_files(paths) -> None:
    """Check that every file is one of ours, of this schema (one clear error otherwise)."""
    for path in paths:
        read_meta(path)


def read_dataset(directory: Path) -> pd.DataFrame:
    """A Hive-partitioned tree of our files as one frame, ``cell_id`` as a string column.

    The same as ``pd.read_parquet(directory)``, except that the partition column is typed
    as a string explicitly (pandas' inference would turn an all-digit id into a number),
    and that the files' schemas are unified: runs stored before an option existed lack
    its column, which then reads as null for them instead of being dropped for all.
    """
    import pyarrow.dataset as ds

    partitioning = ds.partitioning(pa.schema([(PARTITION, pa.string())]), flavor="hive")
    try:
        dataset = ds.dataset(directory, format="parquet", partitioning=partitioning)
        schemas = [f.physical_schema for f in dataset.get_fragments()]
        if schemas:
            unified = pa.unify_schemas([sc.remove_metadata() for sc in schemas] +
                                       [pa.schema([(PARTITION, pa.string())])], promote_options="default")
            dataset = ds.dataset(directory, format="parquet", partitioning=partitioning, schema=unified)
        return dataset.to_table().to_pandas()
    except (OSError, pa.ArrowException) as exc:
        raise TanbenchError(f"{directory}: cannot read the results ({str(exc).splitlines()[0]})") from None


def remove_stale_temporaries(out: Path) -> list[Path]:
    """Delete the temporary files (``.<name>.<pid>.tmp``, write probes) of killed writers.

    A sweep killed while writing (SIGKILL, power loss) leaves its temporary file; readers
    ignore it (``pd.read_parquet`` skips names starting with a dot) but it is clutter.
    A temporary whose writer process is still alive (another sweep writing into the same
    directory) is kept.
    """
    removed = []
    if not out.is_dir():
        return removed
    for path in [*out.rglob(".*.tmp"), *out.glob(".write-test.*")]:
        pid = path.name.removesuffix(".tmp").rsplit(".", 1)[-1]
        if pid.isdigit() and int(pid) != os.getpid() and _alive(int(pid)):
            continue
        try:
            path.unlink()
            removed.append(path)
        except OSError:
            pass
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: alive, someone else's
        return True
    return True


LOCK_FILE = ".tanbench.lock"


@contextmanager
def directory_lock(out: Path):
    """Hold ``out``'s lock while a sweep writes there: a second ``tanbench run`` into the same directory is refused
    with one line (it would compute the same tasks again). ``fcntl.flock`` on ``out/.tanbench.lock``, released by the
    system when the process ends however it ends (no stale lock after a kill); the file, holding the writer's pid,
    is removed when the lock is let go, so a directory looks the same after a run as before. Where ``fcntl`` is
    missing (Windows) nothing is locked."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    path = out / LOCK_FILE
    while True:
        try:
            fh = open(path, "a+")
        except FileNotFoundError:  # out was removed meanwhile (a refused run that had created it)
            raise TanbenchError(f"{out} was removed while this run started; run it again") from None
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            pid = fh.read().strip()
            fh.close()
            raise TanbenchError(f"{out} is being written by another tanbench run{f' (pid {pid})' if pid else ''}: "
                                f"wait for it to end, or use another --out") from None
        try:
            same = os.fstat(fh.fileno()).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:  # not a file a writer that just ended had unlinked: ours
            break
        fh.close()
    try:
        fh.seek(0)
        fh.truncate()
        fh.write(str(os.getpid()))
        fh.flush()
        yield
    finally:
        path.unlink(missing_ok=True)
        fh.close()


def check_directory_path(out: Path) -> None:
    """Refuse an output path that is, or lies under, a file (creates nothing)."""
    if out.exists() and not out.is_dir():
        raise TanbenchError(f"output directory {out} is a file, not a directory (give --out a directory)")
    for parent in out.parents:
        if parent.exists() and not parent.is_dir():
            raise TanbenchError(f"output directory {out}: {parent} is a file, not a directory")


def check_writable(out: Path) -> None:
    """Create ``out`` if needed and make sure files can be written there."""
    check_directory_path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".write-test.{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise TanbenchError(f"output directory {out} is not writable ({exc.strerror or exc})") from None
