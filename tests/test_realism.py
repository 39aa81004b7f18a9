"""Simulated frames against the real MMAUD sample: the statistics a reader or estimator relies on.

Run with ``-s`` to print a side-by-side table (real vs simulated). Each test states its tolerance.
The real files are read directly with numpy; nothing from them is copied.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cldet.simulate import simulate_sequence
from cldet.stamps import parse_stamp

# Scenarios of the simulated side: the drone mostly outside the Avia cone, as in the real sample
# after its first 3 s; plus one "mixed" flight.
SIM_SCENARIOS = ("close_pass", "hover", "person", "mixed")


@dataclass(frozen=True)
class Stats:
    """Per-modality statistics of one or more sequence folders."""

    mid_valid: np.ndarray  # (F,) valid rows per Mid-360 frame (merged 40032-row frames excluded)
    mid_sizes: list[int]  # rows per Mid-360 file, in stamp order
    mid_valid_fraction: float
    mid_zero_packets: float  # fraction of 96-row packets that are entirely zero
    mid_el: np.ndarray  # elevations (deg) of valid points farther than 0.15 m
    mid_range: np.ndarray  # ranges (m) of valid points
    mid_z: np.ndarray  # z (m) of valid points
    mid_self_returns: float  # points within 0.1 m of the origin per frame
    mid_period_ms: np.ndarray  # Mid-360 stamp differences (single-frame gaps only)
    avia_rows: set[tuple[int, int]]
    avia_valid: np.ndarray  # (F,) valid rows per Avia frame
    avia_el: np.ndarray  # elevations (deg) of valid Avia points
    avia_range: np.ndarray  # ranges (m) of valid Avia points
    avia_zero_signature: bool  # every zero row is (-0.0, -0.0, +0.0)
    avia_offset_ms: np.ndarray  # Avia stamp - nearest earlier Mid-360 stamp
    radar_empty: float  # fraction of radar frames of shape (0,)
    radar_repeat: float  # fraction of non-empty radar frames equal to the previous frame
    radar_bad_shapes: int  # frames neither (0,) nor (N, 3)
    radar_period_ms: np.ndarray


def _stamped(folder: Path) -> list[tuple[int, Path]]:
    return sorted((parse_stamp(p.name[: -len(".npy")]), p) for p in folder.glob("*.npy"))


def _elevation(p: np.ndarray) -> np.ndarray:
    r = np.linalg.norm(p, axis=1)
    return np.degrees(np.arcsin(np.clip(p[:, 2] / np.maximum(r, 1e-12), -1, 1)))


def collect(seq_dirs: list[Path]) -> Stats:
    """Statistics over the given sequence folders."""
    mid_valid, mid_sizes, el, rng_, z, zero_packets, periods = [], [], [], [], [], [], []
    self_returns = 0
    n_mid = 0
    rows_total = valid_total = 0
    avia_rows, avia_valid, avia_el, avia_range, offsets = set(), [], [], [], []
    signature = True
    radar_shapes, radar_repeat, radar_nonempty, radar_periods = [], 0, 0, []
    for seq in seq_dirs:
        mids = _stamped(seq / "lidar_360")
        mid_stamps = np.array([s for s, _ in mids])
        d = np.diff(mid_stamps) / 1e6
        periods.append(d[d < 150])
        for _, path in mids:
            a = np.load(path)
            mid_sizes.append(a.shape[0])
            valid = np.any(a != 0, axis=1)
            rows_total += len(a)
            valid_total += int(valid.sum())
            if a.shape[0] > 30000:
                continue
            n_mid += 1
            mid_valid.append(int(valid.sum()))
            packets = valid[: len(valid) // 96 * 96].reshape(-1, 96).sum(axis=1)
            zero_packets.append(float((packets == 0).mean()))
            p = a[valid]
            r = np.linalg.norm(p, axis=1)
            self_returns += int((r < 0.1).sum())
            el.append(_elevation(p[r > 0.15]))
            rng_.append(r)
            z.append(p[:, 2])
        for stamp, path in _stamped(seq / "livox_avia"):
            a = np.load(path)
            avia_rows.add(a.shape)
            valid = np.any(a != 0, axis=1)
            avia_valid.append(int(valid.sum()))
            zr = a[~valid]
            signature &= bool(
                np.signbit(zr[:, 0]).all()
                and np.signbit(zr[:, 1]).all()
                and not np.signbit(zr[:, 2]).any()
            )
            avia_el.append(_elevation(a[valid]))
            avia_range.append(np.linalg.norm(a[valid], axis=1))
            before = mid_stamps[mid_stamps <= stamp]
            if len(before):
                offsets.append((stamp - before[-1]) / 1e6)
        previous = None
        radar = _stamped(seq / "radar_enhance_pcl")
        radar_periods.append(np.diff([s for s, _ in radar]) / 1e6)
        for _, path in radar:
            a = np.load(path)
            radar_shapes.append(a.shape)
            if a.ndim == 2 and a.shape[0] > 0:
                radar_nonempty += 1
                if (
                    previous is not None
                    and previous.shape == a.shape
                    and np.array_equal(previous, a)
                ):
                    radar_repeat += 1
            previous = a
    return Stats(
        mid_valid=np.array(mid_valid),
        mid_sizes=mid_sizes,
        mid_valid_fraction=valid_total / rows_total,
        mid_zero_packets=float(np.mean(zero_packets)),
        mid_el=np.concatenate(el),
        mid_range=np.concatenate(rng_),
        mid_z=np.concatenate(z),
        mid_self_returns=self_returns / n_mid,
        mid_period_ms=np.concatenate(periods),
        avia_rows=avia_rows,
        avia_valid=np.array(avia_valid),
        avia_el=np.concatenate(avia_el),
        avia_range=np.concatenate(avia_range),
        avia_zero_signature=signature,
        avia_offset_ms=np.array(offsets),
        radar_empty=float(np.mean([s == (0,) for s in radar_shapes])),
        radar_repeat=radar_repeat / max(radar_nonempty, 1),
        radar_bad_shapes=sum(
            1 for s in radar_shapes if not (s == (0,) or (len(s) == 2 and s[1] == 3))
        ),
        radar_period_ms=np.concatenate(radar_periods),
    )


@pytest.fixture(scope="module")
def real(real_sample: Path) -> Stats:
    """Statistics of the real validation sequence."""
    return collect([real_sample / "val" / "seq0001"])


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Stats:
    """Statistics of four simulated 5 s sequences (fixed seeds)."""
    root = tmp_path_factory.mktemp("realism")
    dirs = []
    for i, scenario in enumerate(SIM_SCENARIOS):
        seq = root / scenario
        simulate_sequence(seq, seed=[2024, i], duration_s=5.0, scenario=scenario, images=False)
        dirs.append(seq)
    return collect(dirs)


def _pct(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) if len(a) else float("nan")


def test_print_side_by_side_table(real: Stats, sim: Stats) -> None:
    """Print real vs simulated (visible with ``pytest -s``)."""
    rows = [
        ("Mid-360 valid rows/frame min", real.mid_valid.min(), sim.mid_valid.min()),
        ("Mid-360 valid rows/frame median", np.median(real.mid_valid), np.median(sim.mid_valid)),
        ("Mid-360 valid rows/frame max", real.mid_valid.max(), sim.mid_valid.max()),
        ("Mid-360 valid row fraction", real.mid_valid_fraction, sim.mid_valid_fraction),
        ("Mid-360 all-zero 96-row packets", real.mid_zero_packets, sim.mid_zero_packets),
        ("Mid-360 row counts seen", sorted(set(real.mid_sizes)), sorted(set(sim.mid_sizes))),
        ("Mid-360 elevation min (deg)", real.mid_el.min(), sim.mid_el.min()),
        ("Mid-360 elevation max (deg)", real.mid_el.max(), sim.mid_el.max()),
        ("Mid-360 share below 0 deg", (real.mid_el < 0).mean(), (sim.mid_el < 0).mean()),
        ("Mid-360 share above 12 deg", (real.mid_el > 12).mean(), (sim.mid_el > 12).mean()),
        ("Mid-360 range median (m)", np.median(real.mid_range), np.median(sim.mid_range)),
        ("Mid-360 range p99 (m)", _pct(real.mid_range, 99), _pct(sim.mid_range, 99)),
        ("Mid-360 range max (m)", real.mid_range.max(), sim.mid_range.max()),
        ("Mid-360 z p5 (m, ground)", _pct(real.mid_z, 5), _pct(sim.mid_z, 5)),
        ("Mid-360 self-returns/frame", real.mid_self_returns, sim.mid_self_returns),
        ("Mid-360 period median (ms)", np.median(real.mid_period_ms), np.median(sim.mid_period_ms)),
        ("Avia array shapes", sorted(real.avia_rows), sorted(sim.avia_rows)),
        ("Avia zero rows (-0,-0,+0)", real.avia_zero_signature, sim.avia_zero_signature),
        (
            "Avia all-zero frame fraction",
            (real.avia_valid == 0).mean(),
            (sim.avia_valid == 0).mean(),
        ),
        ("Avia valid rows/frame median", np.median(real.avia_valid), np.median(sim.avia_valid)),
        ("Avia valid rows/frame max", real.avia_valid.max(), sim.avia_valid.max()),
        ("Avia elevation min (deg)", real.avia_el.min(), sim.avia_el.min()),
        ("Avia range max (m)", real.avia_range.max(), sim.avia_range.max()),
        ("Avia offset median (ms)", np.median(real.avia_offset_ms), np.median(sim.avia_offset_ms)),
        ("Radar empty (0,) fraction", real.radar_empty, sim.radar_empty),
        ("Radar repeats of previous", real.radar_repeat, sim.radar_repeat),
        (
            "Radar period median (ms)",
            np.median(real.radar_period_ms),
            np.median(sim.radar_period_ms),
        ),
    ]
    print()
    print(f"simulated: scenarios {', '.join(SIM_SCENARIOS)}, 5 s each")
    print(f"{'statistic':<34} {'real':>18} {'simulated':>18}")
    for name, a, b in rows:
        fa = f"{a:.3f}" if isinstance(a, float | np.floating) else str(a)
        fb = f"{b:.3f}" if isinstance(b, float | np.floating) else str(b)
        print(f"{name:<34} {fa:>18} {fb:>18}")


def test_mid360_valid_rows_per_frame(real: Stats, sim: Stats) -> None:
    """Median valid rows within 25% of the real median; every frame within 2.5k-6.5k."""
    assert 3900 <= np.median(real.mid_valid) <= 4900  # the sample itself, as documented
    assert abs(np.median(sim.mid_valid) / np.median(real.mid_valid) - 1) < 0.25
    assert sim.mid_valid.min() > 2500 and sim.mid_valid.max() < 6500
    assert abs(sim.mid_valid_fraction - real.mid_valid_fraction) < 0.07


def test_mid360_packets_and_row_counts(real: Stats, sim: Stats) -> None:
    """Zero rows come in whole 96-row packets (share within 0.2 of real); row counts as real."""
    assert abs(sim.mid_zero_packets - real.mid_zero_packets) < 0.2
    assert set(sim.mid_sizes) <= {20064, 19968, 40032}
    assert set(real.mid_sizes) <= {20064, 19968, 40032}
    sizes = [s for s in sim.mid_sizes if s != 40032]
    assert sizes.count(19968) >= 1.5 * sizes.count(20064) * 0.9


def test_mid360_elevation_range_and_shape(real: Stats, sim: Stats) -> None:
    """Valid points between -8 and 53 deg (real reaches 52.8: mm rounding near the sensor), 99.9%
    of them within -7.5..52.5; share below the horizon within 0.2 of real, above 12 deg within 0.1."""
    for s in (real, sim):
        assert s.mid_el.min() > -8.0 and s.mid_el.max() < 53.0
        assert _pct(s.mid_el, 0.05) > -7.5 and _pct(s.mid_el, 99.95) < 52.5
    assert abs((sim.mid_el < 0).mean() - (real.mid_el < 0).mean()) < 0.2
    assert abs((sim.mid_el > 12).mean() - (real.mid_el > 12).mean()) < 0.1


def test_mid360_ranges_ground_and_self_returns(real: Stats, sim: Stats) -> None:
    """Median range within 50% of real, nothing beyond 100 m, ground 5th percentile within 0.35 m."""
    assert abs(np.median(sim.mid_range) / np.median(real.mid_range) - 1) < 0.5
    assert sim.mid_range.max() < 100.0
    assert abs(_pct(sim.mid_z, 5) - _pct(real.mid_z, 5)) < 0.35
    assert real.mid_self_returns > 0.5 and 0.5 < sim.mid_self_returns < 5


def test_avia_signature_elevation_and_zero_frames(real: Stats, sim: Stats) -> None:
    """Avia: (24000, 3), zero rows (-0,-0,+0), valid points >= 52 deg (0.2 deg slack), all-zero
    fraction within 0.2 of real, median valid rows per frame below 10 (drone outside the cone)."""
    assert real.avia_rows == sim.avia_rows == {(24000, 3)}
    assert real.avia_zero_signature and sim.avia_zero_signature
    assert real.avia_el.min() > 51.5 and sim.avia_el.min() > 51.8
    assert abs((sim.avia_valid == 0).mean() - (real.avia_valid == 0).mean()) < 0.2
    assert np.median(sim.avia_valid) < 10


def test_radar_frames_like_real(real: Stats, sim: Stats) -> None:
    """Radar: shapes (0,) or (N, 3); empty fraction within 0.2 of real; most non-empty repeat."""
    assert real.radar_bad_shapes == sim.radar_bad_shapes == 0
    assert abs(sim.radar_empty - real.radar_empty) < 0.2
    assert real.radar_repeat > 0.5 and sim.radar_repeat > 0.4


def test_stamp_spacing(real: Stats, sim: Stats) -> None:
    """Mid-360 every 100 ms (+-1 ms), Avia 14 ms after (+-1.5 ms), radar every 66.7 ms (+-2 ms)."""
    for s in (real, sim):
        assert abs(np.median(s.mid_period_ms) - 100.0) < 1.0
        assert np.abs(s.mid_period_ms - 100.0).max() < 2.0
        assert abs(np.median(s.avia_offset_ms) - 14.0) < 1.5
        assert abs(np.median(s.radar_period_ms) - 66.67) < 2.0
