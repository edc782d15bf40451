"""Floor records for the proof cases: a window of a real accelerogram through a five-storey shear
building (fixed base, T1 = 1.0 s, or base-isolated, T1 = 2.8 s; 5 % modal damping), read at floor 4
or 5, plus a transverse and a vertical component.

Ground motions come from ../shared/data/ground_motions (see its SOURCES.md): PEER AT2, the
SimCenter event JSON and the RENADIC Vol. 1 file, all in g.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import linalg, signal
from scipy.optimize import brentq

G = 9.81
FS = 200.0                 # floor sampling rate, Hz
N_STOREYS = 5
MODAL_DAMPING = 0.05
QUIET_TAIL_S = 6.0         # zeros appended to the ground motion: the building rings down
TAPER_S = 0.5              # half-cosine ramps at both ends of the record window
TRANSVERSE_RATIO = 0.6     # ay peak / ax peak
VERTICAL_RATIO = 0.1       # az peak / ax peak


@dataclass(frozen=True)
class Record:
    """One horizontal component of a real accelerogram, in m/s^2 at FS."""
    file: str
    component: str
    acc: np.ndarray

    @property
    def duration_s(self) -> float:
        return (len(self.acc) - 1) / FS


def _to_fs(acc_g: np.ndarray, dt: float) -> np.ndarray:
    """m/s^2 at FS; records at 100 Hz are upsampled with a polyphase low-pass filter."""
    ratio = FS * dt
    if abs(ratio - round(ratio)) > 1e-9:
        raise ValueError(f"record step {dt} s is not a divisor of 1/{FS:g} s")
    acc = np.asarray(acc_g, float) * G
    return acc if round(ratio) == 1 else signal.resample_poly(acc, round(ratio), 1)


def read_at2(path: Path) -> tuple[np.ndarray, float]:
    """PEER AT2: four header lines (the fourth gives NPTS and DT), then values in g."""
    lines = path.read_text().splitlines()
    head = lines[3]
    m = re.search(r"NPTS\s*=\s*(\d+)\s*,\s*DT\s*=\s*([0-9.Ee+-]+)", head)
    if m:
        npts, dt = int(m.group(1)), float(m.group(2))
    else:   # older layout: "4096    0.0100    NPTS, DT"
        tokens = head.split()
        npts, dt = int(tokens[0]), float(tokens[1])
    values = np.array(" ".join(lines[4:]).split(), float)
    if len(values) != npts:
        raise ValueError(f"{path}: {len(values)} values, the header says {npts}")
    return values, dt


def read_renadic_v1(path: Path) -> dict[str, tuple[np.ndarray, float]]:
    """RENADIC Vol. 1: per channel 13 text, 7 integer and 7 float header lines, then (time, accel)
    pairs in 7-character fields, then one trailer line. Accelerations in g/10, uncorrected."""
    lines = path.read_text().splitlines()
    channels, i = {}, 0
    while i < len(lines) and lines[i].strip():
        code = re.search(r"CHAN\s+\d+:\s*(\w)", "\n".join(lines[i:i + 13])).group(1)
        npts = int(re.search(r"NO\. OF POINTS\s*=\s*(\d+)", "\n".join(lines[i:i + 13])).group(1))
        i += 27
        n_lines = math.ceil(npts / 5)
        fields = [ln[j:j + 7] for ln in lines[i:i + n_lines] for j in range(0, len(ln.rstrip()), 7)]
        pairs = np.array([float(x) for x in fields if x.strip()]).reshape(-1, 2)
        if len(pairs) != npts:
            raise ValueError(f"{path}: channel {code} has {len(pairs)} samples, the header says {npts}")
        dt = float(np.median(np.diff(pairs[:, 0])))
        channels[code] = (pairs[:, 1] / 10.0, dt)
        i += n_lines + 1
    return channels


def load_records(motions_dir: Path) -> list[Record]:
    """Every horizontal component in the folder (verticals are left out: the vertical floor motion
    is built from the building's slab mode)."""
    records = []
    for path in sorted(motions_dir.glob("*.AT2")):
        if path.stem.upper().endswith("UP"):
            continue
        acc, dt = read_at2(path)
        records.append(Record(path.name, "horizontal", _to_fs(acc, dt)))
    for path in sorted(motions_dir.glob("*.json")):
        event = json.loads(path.read_text())
        for comp in ("x", "y"):
            records.append(Record(path.name, comp, _to_fs(np.array(event[f"data_{comp}"]), event["dT"])))
    for path in sorted(motions_dir.glob("*.v1")):
        for code, (acc, dt) in read_renadic_v1(path).items():
            if code == "V":
                continue
            # Uncorrected: remove a least-squares cubic in time, as the study did.
            tt = np.linspace(-1.0, 1.0, len(acc))
            acc = acc - np.polyval(np.polyfit(tt, acc, 3), tt)
            records.append(Record(path.name, code, _to_fs(acc, dt)))
    if not records:
        raise FileNotFoundError(f"no ground motions in {motions_dir}")
    return records


# -- the building ---------------------------------------------------------------------------------
def sdof_absolute_acceleration(base: np.ndarray, fn_hz: float, zeta: float, fs: float = FS) -> np.ndarray:
    """Absolute acceleration of a linear oscillator (natural frequency fn_hz, damping ratio zeta)
    under the base acceleration `base`, by exact discretisation for a base motion linear between
    samples (first-order hold), run as a recursive filter."""
    wn = 2 * math.pi * fn_hz
    A = np.array([[0.0, 1.0], [-wn ** 2, -2 * zeta * wn]])
    B = np.array([[0.0], [-1.0]])            # relative motion driven by -base
    C = np.array([[-wn ** 2, -2 * zeta * wn]])   # relative + base acceleration = absolute
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, np.zeros((1, 1))), 1.0 / fs, method="foh")
    num, den = signal.ss2tf(Ad, Bd, Cd, Dd)
    return signal.lfilter(num[0], den, base)


@dataclass(frozen=True)
class Building:
    """A linear shear building by modal superposition: the absolute acceleration of floor j is
    sum_n phi_jn Gamma_n A_n(t), A_n the absolute acceleration of mode n's unit oscillator."""
    kind: str                  # "fixed" or "isolated"
    periods_s: tuple
    contributions: np.ndarray  # [floor 1..5, mode]: phi_jn Gamma_n
    floor_offset: int          # row of floor 1 (the isolated base slab is row 0)

    def floor_response(self, ground: np.ndarray, floor: int) -> np.ndarray:
        row = self.contributions[self.floor_offset + floor - 1]
        return sum(c * sdof_absolute_acceleration(ground, 1.0 / T, MODAL_DAMPING)
                   for c, T in zip(row, self.periods_s))


def _shear_stiffness(stiffness: np.ndarray) -> np.ndarray:
    """Stiffness matrix of a chain of storeys, storey i joining level i-1 (level -1 = ground)."""
    n = len(stiffness)
    K = np.zeros((n, n))
    for i, k in enumerate(stiffness):
        K[i, i] += k
        if i > 0:
            K[i - 1, i - 1] += k
            K[i - 1, i] -= k
            K[i, i - 1] -= k
    return K


def _first_period(K: np.ndarray, M: np.ndarray) -> float:
    return 2 * math.pi / math.sqrt(linalg.eigh(K, M, eigvals_only=True)[0])


def make_building(kind: str) -> Building:
    """Uniform storeys (unit masses, equal stiffness) scaled to T1 = 1.0 s; the isolated building is
    the same superstructure on a base slab (one more unit mass) whose isolators give T1 = 2.8 s."""
    M = np.eye(N_STOREYS)
    K = _shear_stiffness(np.ones(N_STOREYS))
    K *= (_first_period(K, M) / 1.0) ** 2
    offset = 0
    if kind == "isolated":
        k_storey = K[-1, -1]
        M = np.eye(N_STOREYS + 1)

        def period_gap(k_iso):
            return _first_period(_shear_stiffness(np.r_[k_iso, np.full(N_STOREYS, k_storey)]), M) - 2.8
        k_iso = brentq(period_gap, 1e-6 * k_storey, k_storey)
        K = _shear_stiffness(np.r_[k_iso, np.full(N_STOREYS, k_storey)])
        offset = 1
    elif kind != "fixed":
        raise ValueError(f"building kind {kind!r}: fixed or isolated")
    w2, phi = linalg.eigh(K, M)              # mass-normalised modes
    gamma = phi.T @ M @ np.ones(len(M))      # participation factors
    periods = tuple(float(p) for p in 2 * math.pi / np.sqrt(w2))
    return Building(kind, periods, phi * gamma, offset)


# -- a floor record ------------------------------------------------------------------------------
def arias_times(acc: np.ndarray) -> tuple[float, float]:
    """Times at which the Arias intensity reaches 5 % and 95 % of its total."""
    cum = np.cumsum(acc ** 2)
    cum /= cum[-1]
    return np.searchsorted(cum, 0.05) / FS, np.searchsorted(cum, 0.95) / FS


def _taper(n: int) -> np.ndarray:
    ramp = int(TAPER_S * FS)
    w = np.ones(n)
    half = 0.5 * (1 - np.cos(np.pi * np.arange(ramp) / ramp))
    w[:ramp], w[-ramp:] = half, half[::-1]
    return w


def _envelope(acc: np.ndarray, seconds: float = 1.0) -> np.ndarray:
    """Moving RMS, normalised to a peak of 1."""
    width = int(seconds * FS)
    rms = np.sqrt(np.convolve(acc ** 2, np.ones(width) / width, mode="same"))
    return rms / rms.max()


def _phase_randomised(acc: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Same amplitude spectrum, random phases, under the original's envelope."""
    spec = np.fft.rfft(acc)
    phases = np.exp(1j * rng.uniform(0, 2 * np.pi, len(spec)))
    phases[0] = 1.0
    copy = np.fft.irfft(np.abs(spec) * phases, len(acc))
    return copy * _envelope(acc, 2.0) / max(_envelope(copy, 2.0).max(), 1e-12)


def _vertical(ground: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Vertical floor motion: band-passed (5-15 Hz) noise under the ground motion's envelope,
    through the floor slab's vertical mode (an SDOF at 8-14 Hz, 5 % damping)."""
    sos = signal.butter(4, [5.0, 15.0], btype="bandpass", fs=FS, output="sos")
    excitation = signal.sosfiltfilt(sos, rng.standard_normal(len(ground))) * _envelope(ground)
    fn, zeta = rng.uniform(8.0, 14.0), 0.05
    az = sdof_absolute_acceleration(excitation, fn, zeta)
    return az, {"excitation": "band-passed noise 5-15 Hz under the ground motion's envelope",
                            "slab_fn_hz": round(fn, 3), "slab_zeta": zeta, "peak_ratio_to_ax": VERTICAL_RATIO}


@dataclass
class FloorRecord:
    ax: np.ndarray
    ay: np.ndarray
    az: np.ndarray
    info: dict

    @property
    def duration_s(self) -> float:
        return (len(self.ax) - 1) / FS


def make_floor(rng: np.random.Generator, records: list[Record], buildings: dict, threshold_mps2: float,
               ratio: float) -> FloorRecord:
    """A random record window through a random building to floor 4 or 5, scaled so that the peak
    floor acceleration is `ratio` times the uplift threshold g tan(alpha)."""
    rec = records[rng.integers(len(records))]
    t5, t95 = arias_times(rec.acc)
    start = max(0.0, t5 - rng.uniform(1.5, 3.0))
    length = rng.uniform(25.0, 45.0)
    i0, n_win = int(round(start * FS)), int(round(length * FS))
    window = rec.acc[i0:i0 + n_win]
    padded_s = (n_win - len(window)) / FS      # a window running past the record's end is zero there
    ground = np.r_[window * _taper(len(window)), np.zeros(n_win - len(window) + int(QUIET_TAIL_S * FS))]
    building = buildings[rng.choice(["fixed", "isolated"])]
    level = int(rng.choice([4, 5]))
    ax = building.floor_response(ground, level)
    scale = ratio * threshold_mps2 / np.abs(ax).max()
    ground, ax = ground * scale, ax * scale
    ay = building.floor_response(_phase_randomised(ground, rng), level)
    ay *= TRANSVERSE_RATIO * np.abs(ax).max() / np.abs(ay).max()
    az, vertical = _vertical(ground, rng)
    az *= VERTICAL_RATIO * np.abs(ax).max() / np.abs(az).max()
    # The floor is written with 6 decimals; every simulation uses the values as written.
    ax, ay, az = (np.round(c, 6) for c in (ax, ay, az))
    w5, w95 = arias_times(ground)
    info = {
        "pfa_mps2": float(np.abs(ax).max()),
        "pfa_g": float(np.abs(ax).max() / G),
        "pfa_over_uplift_threshold": float(np.abs(ax).max() / threshold_mps2),
        "uplift_threshold_mps2": threshold_mps2,
        "duration_s": (len(ax) - 1) / FS,
        "building": building.kind,
        "floor": level,
        "fundamental_period_s": round(building.periods_s[0], 4),
        "periods_s": [round(p, 4) for p in building.periods_s],
        "modal_damping": MODAL_DAMPING,
        "fs_hz": FS,
        "ground_motion": {
            "source": "recorded",
            "file": rec.file,
            "component": rec.component,
            "window_in_record_s": [round(start, 3), round(start + length, 3)],
            "zero_padded_past_record_end_s": round(padded_s, 3),
            "scale_factor": float(scale),
            "scaled_pga_g": float(np.abs(ground).max() / G),
            "arias_5_95_s": [round(w5, 3), round(w95, 3)],
            "transverse": "phase-randomised copy of the in-plane ground window through the same building",
        },
        "vertical": vertical,
        "transverse_peak_ratio_to_ax": TRANSVERSE_RATIO,
        "quiet_tail_s": QUIET_TAIL_S,
    }
    return FloorRecord(ax, ay, az, info)
