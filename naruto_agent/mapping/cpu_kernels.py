"""Compiled CPU loops for evaluating the neural field without gradients.

Queries that need no gradient (scoring the active-sampling pool, reading the planner view,
meshing) evaluate the hash grid on hundreds of thousands of points. The PyTorch path
materialises the eight corners' table rows and weights of every hashed level as arrays
(``8 x levels x N`` of each, about 90 MB for 100,000 points) before it gathers and blends
them: memory traffic, not arithmetic, bounds it. The loop here walks each point's levels and
corners once, keeps the blend in registers and writes only the ``levels x features`` output
(less CPU time than the PyTorch path, most on spatially coherent points such as the samples
along rays; ``benchmarks/active_scoring_speed.py`` measures it). It computes the same
function (the same corners, rows and trilinear weights, in float32; results agree to float
rounding).

The loops are serial and release the GIL (``nogil``); :func:`hash_grid_features` splits the
points over a few Python threads (the project's shared pool, ``run_parallel``). (A numba
parallel threading layer would have to coexist with torch's OpenMP pool and the renderer's
threads; plain threads do not.)
"""

from __future__ import annotations

import numba
import numpy as np

from naruto_gym.utils.threads import resolve_threads, run_parallel

# Below this many points a single call beats the threads' hand-off.
_MIN_POINTS_PER_THREAD = 8192


@numba.njit(cache=True, nogil=True, boundscheck=False)
def _hash_grid_kernel(
    unit: np.ndarray,
    table: np.ndarray,
    scales: np.ndarray,
    multipliers: np.ndarray,
    num_dense: int,
    table_size: int,
    out: np.ndarray,
    column: int,
) -> None:
    """Trilinear hash-grid features of points (two features per level).

    Args:
        unit: (N, 3) float32 positions in [0, 1].
        table: (2, L * T) float32 feature table, level ``l`` in rows ``[l T, (l + 1) T)``.
        scales: (L,) float32 grid resolution of each level.
        multipliers: (3, L) int64 per-axis row multipliers: (1, S, S^2) on dense levels
            (no hashing), the hash primes reduced modulo T on hashed levels.
        num_dense: the first ``num_dense`` levels are dense.
        table_size: T, a power of two.
        out: (N, >= column + 2 L) float32 output; the features go to columns
            ``column + 2 l + f``, level-major.
        column: first output column.
    """
    mask = table_size - 1
    t0 = table[0]
    t1 = table[1]
    for n in range(unit.shape[0]):
        ux = unit[n, 0]
        uy = unit[n, 1]
        uz = unit[n, 2]
        for level in range(scales.shape[0]):
            scale = scales[level]
            px = ux * scale
            py = uy * scale
            pz = uz * scale
            # Positions are >= 0, so truncation is the floor.
            cx = int(px)
            cy = int(py)
            cz = int(pz)
            wx1 = px - np.float32(cx)
            wy1 = py - np.float32(cy)
            wz1 = pz - np.float32(cz)
            wx0 = np.float32(1.0) - wx1
            wy0 = np.float32(1.0) - wy1
            wz0 = np.float32(1.0) - wz1
            x0 = cx * multipliers[0, level]
            x1 = x0 + multipliers[0, level]
            y0 = cy * multipliers[1, level]
            y1 = y0 + multipliers[1, level]
            z0 = cz * multipliers[2, level]
            z1 = z0 + multipliers[2, level]
            if level < num_dense:
                r000, r001, r010, r011 = x0 + y0 + z0, x0 + y0 + z1, x0 + y1 + z0, x0 + y1 + z1
                r100, r101, r110, r111 = x1 + y0 + z0, x1 + y0 + z1, x1 + y1 + z0, x1 + y1 + z1
            else:
                r000 = (x0 ^ y0 ^ z0) & mask
                r001 = (x0 ^ y0 ^ z1) & mask
                r010 = (x0 ^ y1 ^ z0) & mask
                r011 = (x0 ^ y1 ^ z1) & mask
                r100 = (x1 ^ y0 ^ z0) & mask
                r101 = (x1 ^ y0 ^ z1) & mask
                r110 = (x1 ^ y1 ^ z0) & mask
                r111 = (x1 ^ y1 ^ z1) & mask
            offset = level * table_size
            r000 += offset
            r001 += offset
            r010 += offset
            r011 += offset
            r100 += offset
            r101 += offset
            r110 += offset
            r111 += offset
            w00 = wx0 * wy0
            w01 = wx0 * wy1
            w10 = wx1 * wy0
            w11 = wx1 * wy1
            a000, a001, a010, a011 = w00 * wz0, w00 * wz1, w01 * wz0, w01 * wz1
            a100, a101, a110, a111 = w10 * wz0, w10 * wz1, w11 * wz0, w11 * wz1
            out[n, column + 2 * level] = (
                a000 * t0[r000] + a001 * t0[r001] + a010 * t0[r010] + a011 * t0[r011]
                + a100 * t0[r100] + a101 * t0[r101] + a110 * t0[r110] + a111 * t0[r111]
            )  # fmt: skip
            out[n, column + 2 * level + 1] = (
                a000 * t1[r000] + a001 * t1[r001] + a010 * t1[r010] + a011 * t1[r011]
                + a100 * t1[r100] + a101 * t1[r101] + a110 * t1[r110] + a111 * t1[r111]
            )  # fmt: skip


@numba.njit(cache=True, nogil=True, boundscheck=False)
def _one_blob_kernel(unit: np.ndarray, bins: int, cutoff: float, out: np.ndarray) -> None:
    """OneBlob encoding of points into ``out[:, :3 * bins]`` (axis-major, bin-minor).

    Bin ``b`` of a coordinate ``u`` is ``exp(-(t - b)^2 / 2)`` with ``t = bins u - 1/2``
    (kernel width one bin), 0 beyond ``cutoff`` bins. Three exponentials per axis instead of
    one per bin: from the nearest bin ``m`` outwards, neighbouring values differ by the
    factor ``exp(+-(t - m) - 1/2) exp(-k)`` at distance ``k`` (computed in float64).
    """
    decay = np.exp(-np.arange(bins).astype(np.float64))
    cutoff_squared = cutoff * cutoff
    for n in range(unit.shape[0]):
        for axis in range(3):
            t = np.float64(unit[n, axis]) * bins - 0.5
            m = min(max(int(np.floor(t + 0.5)), 0), bins - 1)
            d = t - m
            centre = np.exp(-0.5 * d * d)
            base = axis * bins
            out[n, base + m] = centre if d * d <= cutoff_squared else 0.0
            up = np.exp(d - 0.5)
            value = centre
            for b in range(m + 1, bins):
                value *= up * decay[b - 1 - m]
                gap = t - b
                out[n, base + b] = value if gap * gap <= cutoff_squared else 0.0
            down = np.exp(-d - 0.5)
            value = centre
            for b in range(m - 1, -1, -1):
                value *= down * decay[m - 1 - b]
                gap = t - b
                out[n, base + b] = value if gap * gap <= cutoff_squared else 0.0


def _field_inputs_part(
    unit: np.ndarray,
    table: np.ndarray,
    scales: np.ndarray,
    multipliers: np.ndarray,
    num_dense: int,
    table_size: int,
    bins: int,
    cutoff: float,
    out: np.ndarray,
) -> None:
    _one_blob_kernel(unit, bins, cutoff, out)
    _hash_grid_kernel(unit, table, scales, multipliers, num_dense, table_size, out, 3 * bins)


def supports(features_per_level: int) -> bool:
    """Whether the compiled loop handles this layout (two features per level, published)."""
    return features_per_level == 2


def _run_split(function, unit: np.ndarray, out: np.ndarray, threads: int | None, *args) -> None:  # noqa: ANN001, E501
    """Run ``function(unit[part], *args, out[part])`` over row ranges on up to ``threads``
    threads (None: :func:`~naruto_gym.utils.threads.default_thread_count`; one call for
    small inputs)."""
    count = unit.shape[0]
    parts = max(1, min(resolve_threads(threads), count // _MIN_POINTS_PER_THREAD))
    if parts == 1:
        function(unit, *args, out)
        return
    bounds = np.linspace(0, count, parts + 1).astype(np.int64)
    run_parallel(
        lambda k: function(unit[bounds[k]:bounds[k + 1]], *args, out[bounds[k]:bounds[k + 1]]),
        parts,
    )


def hash_grid_features(
    unit: np.ndarray,
    table: np.ndarray,
    scales: np.ndarray,
    multipliers: np.ndarray,
    num_dense: int,
    table_size: int,
    threads: int | None = None,
) -> np.ndarray:
    """(N, 2 L) float32 hash-grid features of (N, 3) unit positions (see the kernel).

    The points are split over ``threads`` threads (the loop releases the GIL; None: the
    default count, every CPU the process may use).
    """
    unit = np.ascontiguousarray(unit, dtype=np.float32)
    table = np.ascontiguousarray(table, dtype=np.float32)
    out = np.empty((unit.shape[0], scales.shape[0] * table.shape[0]), dtype=np.float32)

    def part(unit_part, *args):  # noqa: ANN001, ANN002, ANN202
        *constants, out_part = args
        _hash_grid_kernel(unit_part, *constants, out_part, 0)

    _run_split(part, unit, out, threads, table, scales, multipliers, num_dense, table_size)
    return out


def field_inputs(
    unit: np.ndarray,
    table: np.ndarray,
    scales: np.ndarray,
    multipliers: np.ndarray,
    num_dense: int,
    table_size: int,
    bins: int,
    cutoff: float,
    threads: int | None = None,
) -> np.ndarray:
    """(N, 3 bins + 2 L) float32 geometry-decoder input of (N, 3) unit positions: the
    OneBlob encoding, then the hash-grid features (``NeuralField``'s concatenation)."""
    unit = np.ascontiguousarray(unit, dtype=np.float32)
    table = np.ascontiguousarray(table, dtype=np.float32)
    out = np.empty((unit.shape[0], 3 * bins + scales.shape[0] * table.shape[0]), np.float32)
    _run_split(
        _field_inputs_part,
        unit,
        out,
        threads,
        table,
        scales,
        multipliers,
        num_dense,
        table_size,
        bins,
        float(cutoff),
    )
    return out
