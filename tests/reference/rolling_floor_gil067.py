"""The slow isolated floor the rolling peer tests run on: 1989 Loma Prieta, Gilroy - Gavilan Coll.
comp 067 (../shared/data/ground_motions, PEER RSN763) through prove/floors.py's base-isolated
five-storey shear building (T1 = 2.8 s), floor 4, scaled to a peak floor acceleration of 0.15 g
along X; Y is the same ground motion reversed in time through the same building, at 0.6 of X's
peak. 40 s at 200 Hz, written with 6 decimals.

    rolling_floor_gil067.py > rolling_floor_gil067_isolated.csv
"""
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "prove"))
import floors  # noqa: E402

G = 9.80665
PFA_G = 0.15

acc, dt = floors.read_at2(ROOT.parent / "shared/data/ground_motions/RSN763_LOMAP_GIL067.AT2")
ground = acc * G
building = floors.make_building("isolated")
ax = building.floor_response(ground, 4)
ay = building.floor_response(ground[::-1].copy(), 4)
ax *= PFA_G * G / np.abs(ax).max()
ay *= 0.6 * PFA_G * G / np.abs(ay).max()
ax[0] = ay[0] = 0.0
print("time_s,ax_mps2,ay_mps2")
for k in range(len(ax)):
    print(f"{float(round(k * dt, 6))!r},{float(round(ax[k], 6))!r},{float(round(ay[k], 6))!r}")
