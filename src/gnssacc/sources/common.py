"""Helpers shared by all sources: the IMU mounting, a fast CSV table reader, range checks.

Every source must pass its IMU samples through :func:`apply_mounting` exactly once, so that the
``[mounting]`` configuration means the same thing whatever the data came from.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Sequence

import numpy as np

from ..core.config import RunConfig
from ..core.errors import InputError, warn_data
from ..core.recording import ImuData, RecordedRun, Truth, drop_nonfinite
from .gnss_noise import fixes_from_truth


def apply_mounting(imu: ImuData, cfg: RunConfig) -> ImuData:
    """Rotate IMU-axis samples into the body frame and put their times on the GNSS clock.

    Parameters
    ----------
    imu : ImuData
        Samples in the IMU's own axes (FRD-labelled: a source that reads FLU data converts to
        FRD first) with time stamps on the IMU clock.
    cfg : RunConfig
        ``mounting.imu_to_body_rpy_deg`` (via ``cfg.R_bi``, ``x_b = R_bi @ x_imu``) and
        ``mounting.imu_time_offset_s`` [s], added to every time stamp. ``"auto"`` stands for the
        identity and zero here: the input checks (:mod:`gnssacc.checks.plausibility`) measure and apply
        them later.

    Returns
    -------
    ImuData
        A new object: body-frame (FRD) specific force [m/s^2] and angular rate [rad/s], times on
        the GNSS clock [s].
    """
    R_bi = cfg.R_bi
    offset_s = configured_time_offset_s(cfg)
    # Row vectors: x_b^T = x_imu^T R_bi^T.
    return ImuData(
        np.asarray(imu.t, float) + offset_s,
        np.asarray(imu.f_b, float) @ R_bi.T,
        np.asarray(imu.omega_ib_b, float) @ R_bi.T,
    )


def configured_time_offset_s(cfg: RunConfig) -> float:
    """``[mounting] imu_time_offset_s`` [s] as a number (``"auto"``: 0 here, measured later); the
    IMU's time stamps and those on its clock (wheel odometry) are shifted by it."""
    value = cfg["mounting"]["imu_time_offset_s"]
    try:
        offset_s = 0.0 if value == "auto" else float(value)
    except (TypeError, ValueError):
        raise InputError(
            "config", '[mounting] imu_time_offset_s must be a number of seconds or "auto"'
        ) from None
    if not np.isfinite(offset_s):
        raise InputError("config", "[mounting] imu_time_offset_s must be finite")
    return offset_s


def with_noisy_fixes(run: RecordedRun, truth: Truth, noise: str, seed: int) -> RecordedRun:
    """``run`` with its GNSS replaced by fixes made from ``truth`` plus simulated noise.

    Parameters
    ----------
    run : RecordedRun
        Supplies the tangent-plane origin (``run.origin``) in which the noise [m, NED] is added.
    truth : Truth
        Positions (geodetic, radians and metres) at the epochs [s] the fixes get.
    noise : str
        GNSS noise profile (:data:`gnssacc.sources.gnss_noise.PROFILES`).
    seed : int
        Noise seed.

    Returns
    -------
    RecordedRun
        A copy with the new fixes and ``noise`` and ``seed`` in ``meta``.
    """
    return run.with_gnss(fixes_from_truth(run, truth, noise, seed), noise=noise, seed=seed)


def one_line(err: Exception) -> str:
    """An exception's text on one line, at most 300 characters (for error and warning messages)."""
    text = " ".join(str(a) for a in err.args) or type(err).__name__
    return " ".join(text.split())[:300]


def check_degrees(
    lat_deg: np.ndarray, lon_deg: np.ndarray, t: np.ndarray, where: str, what: str
) -> None:
    """Raise :class:`InputError` if a latitude or longitude [deg] is out of range.

    ``|lat| <= 90`` and ``|lon| <= 360`` (longitudes in 0..360 are accepted). The message names
    the first offending time stamp.
    """
    for name, values, limit in (("latitude", lat_deg, 90.0), ("longitude", lon_deg, 360.0)):
        bad = np.flatnonzero(np.abs(values) > limit)
        if bad.size:
            k = int(bad[0])
            raise InputError(
                where,
                f"{what} {name} out of range: {values[k]:.6g} deg at t = {t[k]:.6f} s "
                f"(|{name}| must be <= {limit:g} deg); {bad.size} such row(s)",
            )


def text_file_lines(path, kind: str) -> list[str]:
    """The lines of a small text file (a GNSS log), line ends stripped.

    Raises
    ------
    InputError
        Missing file, a directory, or a line that is not text (not UTF-8), naming its number and
        ``kind`` (e.g. "an RTKLIB .pos file").
    """
    where = str(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise InputError(where, "file not found") from None
    except IsADirectoryError:
        raise InputError(where, f"is a directory, expected {kind}") from None
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    lines = raw.splitlines()
    out = []
    for n, line in enumerate(lines, start=1):
        try:
            out.append(line.decode("utf-8"))
        except UnicodeDecodeError:
            raise InputError(
                where, f"line {n} is not text (bytes that are not UTF-8): expected {kind}"
            ) from None
    return out


#: Data lines parsed at once by :func:`read_table`: the text of one block is held at a time, so
#: reading a long recording needs its numbers' memory, not several times its file size.
BLOCK_LINES = 65536


@contextmanager
def _text_lines(path: Path):
    """The file's lines (``\\n`` stripped), read lazily; :class:`InputError` for a missing file,
    a directory or text that is not UTF-8 (also when met half-way through)."""
    try:
        # utf-8-sig: spreadsheets often start CSV files with a byte-order mark.
        with open(path, encoding="utf-8-sig", newline=None) as fh:
            yield (line.rstrip("\n") for line in fh)
    except FileNotFoundError:
        raise InputError(str(path), "file not found") from None
    except IsADirectoryError:
        raise InputError(str(path), "is a directory, expected a CSV file") from None
    except UnicodeDecodeError:
        raise InputError(
            str(path), "not a UTF-8 text file (expected comma-separated values)"
        ) from None


def _data_blocks(lines, first_line_no: int):
    """``(lines, 1-based line numbers, is_last)`` of the data rows in blocks of :data:`BLOCK_LINES`
    (blank and ``#`` comment lines left out); ``is_last`` marks the block holding the file's last
    data row (or an empty block when there is none)."""
    block, numbers, n = [], [], first_line_no
    for line in lines:
        n += 1
        if line.strip() and not line.lstrip().startswith("#"):
            if len(block) == BLOCK_LINES:  # a full block is not the last: another row follows
                yield block, np.asarray(numbers, int), False
                block, numbers = [], []
            block.append(line)
            numbers.append(n)
    yield block, np.asarray(numbers, int), True


def _header_names(line: str) -> list[str]:
    return [c.strip().strip("\"'").strip().lower() for c in line.split(",")]


def _parse_slowly(
    data: list[str], line_no: np.ndarray, usecols: list[int], names: list[str], where: str
) -> np.ndarray:
    """Cell-by-cell parse, only used when the fast parser refused the file.

    Empty cells become NaN (missing values, later dropped with a warning); any other
    non-numeric cell is an error naming its line and column.
    """
    out = np.empty((len(data), len(usecols)))
    for r, line in enumerate(data):
        cells = line.split(",")
        for c, j in enumerate(usecols):
            cell = cells[j].strip()
            if not cell:
                out[r, c] = np.nan
                continue
            try:
                out[r, c] = float(cell)
            except ValueError:
                raise InputError(
                    where,
                    f"non-numeric value {cell[:40]!r} in column '{names[j]}' at line {line_no[r]}",
                ) from None
    return out


def read_table(
    path, required: Sequence[str], optional: Sequence[str] = (), max_bad_fraction: float = 0.01
) -> dict[str, np.ndarray]:
    """Read a comma-separated table with a header line into float columns.

    Header names are matched case-insensitively after stripping blanks and quotes; column order
    is free and extra columns are ignored (they may hold anything). Blank lines and lines whose
    first non-blank character is ``#`` are skipped anywhere in the file. Empty cells count as
    missing (NaN). Rows with NaN/inf in a column that is read are dropped with a
    :class:`~gnssacc.core.errors.DataWarning` giving the count (see :func:`gnssacc.core.recording.drop_nonfinite`).
    A truncated last line (fewer cells than the header, as left by a logger that stopped
    mid-write) is dropped with a warning.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    required : sequence of str
        Lower-case column names that must be present.
    optional : sequence of str
        Lower-case column names returned only when present.
    max_bad_fraction : float
        Largest tolerated fraction of NaN/inf rows (``data.max_bad_fraction``).

    Returns
    -------
    dict of str to ndarray
        One float array of shape (rows,) per required column and per optional column found.
        A file with a header but no data rows gives empty arrays (callers decide if that is
        an error).

    Raises
    ------
    InputError
        Missing or empty file, missing required columns (named, with the header found), a
        repeated column name, a row with the wrong number of cells or a non-numeric cell (with
        its line number), too many NaN/inf rows.
    """
    path = Path(path)
    where = str(path)
    with _text_lines(path) as lines:
        header, n_header = _header_line(lines)
        if header is None:
            raise InputError(
                where, f"empty file: no header line (expected columns {', '.join(required)})"
            )
        names = _header_names(header)
        wanted, usecols = _columns(names, required, optional, where)
        parts = []
        for data, line_no, last in _data_blocks(lines, n_header):
            data, line_no = _check_cell_counts(data, line_no, len(names), where, last)
            if data:
                parts.append(_parse(data, line_no, usecols, names, where))
    if not parts:
        return {c: np.empty(0) for c in wanted}
    # Column-major, so that every column is a contiguous view of the one table (no second copy).
    table = np.empty((sum(len(p) for p in parts), len(wanted)), order="F")
    np.concatenate(parts, axis=0, out=table)
    del parts
    table = np.asfortranarray(drop_nonfinite(table, where, path.stem, float(max_bad_fraction)))
    return {c: table[:, k] for k, c in enumerate(wanted)}  # views: callers copy what they keep


def _header_line(lines) -> tuple[str | None, int]:
    """The first line that is neither blank nor a ``#`` comment, and its 1-based number."""
    for n, line in enumerate(lines, start=1):
        if line.strip() and not line.lstrip().startswith("#"):
            return line, n
    return None, 0


def _columns(names: list[str], required, optional, where: str) -> tuple[list[str], list[int]]:
    """The column names to read (required, then the optional ones present) and their indices."""
    wanted = list(required) + [c for c in optional if c in names]
    missing = [c for c in required if c not in names]
    if missing:
        raise InputError(
            where,
            f"missing required column(s) {', '.join(missing)}; header found: "
            f"{', '.join(names)} (the first non-comment line must be the header)",
        )
    repeated = sorted({c for c in wanted if names.count(c) > 1})
    if repeated:
        raise InputError(
            where, f"column(s) {', '.join(repeated)} appear more than once in the header"
        )
    return wanted, [names.index(c) for c in wanted]


def _parse(
    data: list[str], line_no: np.ndarray, usecols: list[int], names: list[str], where: str
) -> np.ndarray:
    """One block of rows: numpy's parser, or cell by cell when it refuses (empty or bad cells)."""
    try:
        return np.loadtxt(data, delimiter=",", usecols=usecols, ndmin=2, dtype=float, comments=None)
    except ValueError:
        return _parse_slowly(data, line_no, usecols, names, where)


def _check_cell_counts(
    data: list[str], line_no: np.ndarray, n_cols: int, where: str, last: bool = True
):
    """Every data row must have as many cells as the header (a truncated last row of the file,
    the last of its ``last`` block, is dropped)."""
    n_commas = np.fromiter((line.count(",") for line in data), int, len(data))
    bad = np.flatnonzero(n_commas != n_cols - 1)
    if last and bad.size == 1 and bad[0] == len(data) - 1 and n_commas[-1] < n_cols - 1:
        warn_data(
            where,
            f"dropped the truncated last line {line_no[-1]} ({n_commas[-1] + 1} of {n_cols} cells)",
        )
        return data[:-1], line_no[:-1]
    if bad.size:
        k = int(bad[0])
        raise InputError(
            where,
            f"line {line_no[k]} has {n_commas[k] + 1} cells but the header has {n_cols}; "
            f"{bad.size} such line(s)",
        )
    return data, line_no
