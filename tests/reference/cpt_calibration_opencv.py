#!/usr/bin/env python3
"""OpenCV calibrations of synthetic cameras, the oracle for tests/cpt_calibration.rs.

Run: python tests/reference/cpt_calibration_opencv.py   (the venv `make test` makes has OpenCV)
Writes tests/reference/cpt_calibration_opencv.json next to this script.

Each scenario: a camera like the study's (f ~ 1400 px at 1920 x 1080, 3-5 m from the scene,
tilted down 15-35 degrees, optional radial distortion k1), n control points on a floor, a wall and
in the volume between (non-coplanar, all in view), pixels with Gaussian noise sigma, and a grid
of check points on the floor plane Z = 0 with their noise-free pixels. OpenCV calibrates with
cv2.calibrateCamera (one view, CALIB_USE_INTRINSIC_GUESS from a rough K, zero tangential
distortion, k2 = k3 = 0, k1 fixed at 0 for pinhole scenarios); its camera back-projects the check
pixels onto Z = 0 (cv2.undistortPoints, then the ray-plane intersection).
"""
import json
import os

import cv2
import numpy as np

rng = np.random.default_rng(20261122)
SIZE = (1920, 1080)
SCENARIOS = [
    ("n8_sigma0.5_pinhole", 8, 0.5, 0.0),
    ("n12_sigma1.0_pinhole", 12, 1.0, 0.0),
    ("n20_sigma0.5_pinhole", 20, 0.5, 0.0),
    ("n20_sigma1.0_pinhole", 20, 1.0, 0.0),
    ("n12_sigma0.5_k1", 12, 0.5, -0.08),
    ("n20_sigma1.0_k1", 20, 1.0, -0.08),
    ("n16_noise_free_k1", 16, 0.0, -0.08),
]


def look_at(centre, target):
    forward = target - centre
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.array([right, down, forward])
    return rotation, -rotation @ centre


def project(points, rvec, tvec, k, dist):
    pixels, _ = cv2.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, k, dist)
    return pixels.reshape(-1, 2)


def in_view(p):
    return 20 <= p[0] <= SIZE[0] - 20 and 20 <= p[1] <= SIZE[1] - 20


def backproject_floor(pixels, k, dist, rvec, tvec):
    rotation, _ = cv2.Rodrigues(rvec)
    normalised = cv2.undistortPoints(pixels.reshape(-1, 1, 2).astype(np.float64), k, dist).reshape(-1, 2)
    centre = -rotation.T @ tvec.reshape(3)
    out = []
    for x, y in normalised:
        ray = rotation.T @ np.array([x, y, 1.0])
        s = -centre[2] / ray[2]
        out.append(centre + s * ray)
    return np.array(out)


scenarios = []
for name, n, sigma, k1 in SCENARIOS:
    f = 1400.0 * (1 + rng.uniform(-0.03, 0.03))
    k = np.array([[f, 0, 960 + rng.uniform(-15, 15)], [0, f, 540 + rng.uniform(-15, 15)], [0, 0, 1.0]])
    dist = np.array([k1, 0, 0, 0, 0], dtype=float)
    distance = rng.uniform(3000, 5000)
    elevation = np.radians(rng.uniform(15, 35))
    azimuth = np.radians(rng.uniform(-30, 30))
    target = np.array([0.0, 0.0, 700.0])
    centre = target + distance * np.array([np.sin(azimuth) * np.cos(elevation), -np.cos(azimuth) * np.cos(elevation), np.sin(elevation)])
    rotation, tvec = look_at(centre, target)
    rvec, _ = cv2.Rodrigues(rotation)
    world, pixels = [], []
    while len(world) < n:
        kind = len(world) % 3
        if kind == 0:
            w = [rng.uniform(-1500, 1500), rng.uniform(-1500, 1500), 0.0]
        elif kind == 1:
            w = [rng.uniform(-1800, 1800), 1800.0, rng.uniform(100, 2000)]
        else:
            w = [rng.uniform(-1200, 1200), rng.uniform(-1000, 1500), rng.uniform(300, 1600)]
        p = project(np.array(w), rvec, tvec, k, dist)[0]
        if in_view(p):
            world.append(w)
            pixels.append(p + sigma * rng.standard_normal(2))
    world, pixels = np.array(world), np.array(pixels)
    grid = np.array([[x, y, 0.0] for x in np.arange(-1000, 1001, 250) for y in np.arange(-1000, 1001, 250)])
    grid_pixels = project(grid, rvec, tvec, k, dist)
    keep = np.array([in_view(p) for p in grid_pixels])
    grid, grid_pixels = grid[keep], grid_pixels[keep]

    flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
    if k1 == 0.0:
        flags |= cv2.CALIB_FIX_K1
    guess = np.array([[1300.0, 0, 960], [0, 1300.0, 540], [0, 0, 1]])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-15)
    rms, k_cv, dist_cv, rvecs, tvecs = cv2.calibrateCamera(
        [world.astype(np.float32)], [pixels.astype(np.float32)], SIZE, guess, np.zeros(5), flags=flags, criteria=criteria
    )
    back = backproject_floor(grid_pixels, k_cv, dist_cv, rvecs[0], tvecs[0])
    errors = np.linalg.norm(back - grid, axis=1)
    scenarios.append({
        "name": name,
        "sigma_px": sigma,
        "k1_true": k1,
        "world_mm": world.tolist(),
        "pixels": pixels.tolist(),
        "truth": {"K": k.tolist(), "rvec": rvec.ravel().tolist(), "tvec": tvec.ravel().tolist()},
        "plane_world_mm": grid.tolist(),
        "plane_pixels": grid_pixels.tolist(),
        "opencv": {
            "rms_px": rms,
            "K": k_cv.tolist(),
            "dist": dist_cv.ravel().tolist(),
            "plane_backprojected_mm": back.tolist(),
            "plane_error_mean_mm": float(errors.mean()),
            "plane_error_max_mm": float(errors.max()),
        },
    })
    print(f"{name}: OpenCV rms {rms:.4f} px, k1 {dist_cv.ravel()[0]:+.4f}, floor error mean {errors.mean():.3f} mm max {errors.max():.3f} mm")

doc = {"generator": "tests/reference/cpt_calibration_opencv.py", "opencv": cv2.__version__, "numpy": np.__version__, "scenarios": scenarios}
path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "cpt_calibration_opencv.json")
with open(path, "w") as fh:
    json.dump(doc, fh, indent=1)
print(f"wrote {path}")
