#!/usr/bin/env python3
"""OpenCV tracks the frames tests/cpt_tracking.rs renders, side by side with shakeflow.

Usage: cpt_tracking_opencv.py DIR   (DIR holds f0000.png ... and truth.json: start, truth per frame)
Prints one JSON line: RMS errors (px) against the truth of
  - cv2.matchTemplate(TM_CCOEFF_NORMED) of the first frame's 20 px template over a 60 px search
    window around the last position, integer peak refined by a 1D parabola per axis (the usual
    sub-pixel recipe), and
  - cv2.calcOpticalFlowPyrLK frame to frame (21 px window, 3 pyramid levels).
The template is cut exactly as shakeflow cuts it: top-left = round(start - (m - 1) / 2).
"""
import glob
import json
import os
import sys

import cv2
import numpy as np

M, R = 20, 20


def parabola(a, b, c):
    d = a - 2.0 * b + c
    return 0.5 * (a - c) / d if d < 0 else 0.0


def main(directory):
    meta = json.load(open(os.path.join(directory, "truth.json")))
    truth = np.array(meta["truth"], dtype=float)
    start = np.array(meta["start"], dtype=float)
    frames = [cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in sorted(glob.glob(os.path.join(directory, "f*.png")))]
    assert len(frames) == len(truth), (len(frames), len(truth))

    top_left = np.round(start - (M - 1) / 2.0).astype(int)
    offset = start - top_left
    template = frames[0][top_left[1]:top_left[1] + M, top_left[0]:top_left[0] + M]
    position, errors = start.copy(), []
    for k in range(1, len(frames)):
        x0 = int(round(position[0] - offset[0])) - R
        y0 = int(round(position[1] - offset[1])) - R
        window = frames[k][y0:y0 + M + 2 * R, x0:x0 + M + 2 * R]
        scores = cv2.matchTemplate(window, template, cv2.TM_CCOEFF_NORMED)
        _, _, _, (bx, by) = cv2.minMaxLoc(scores)
        dx = parabola(scores[by, bx - 1], scores[by, bx], scores[by, bx + 1]) if 0 < bx < scores.shape[1] - 1 else 0.0
        dy = parabola(scores[by - 1, bx], scores[by, bx], scores[by + 1, bx]) if 0 < by < scores.shape[0] - 1 else 0.0
        position = np.array([x0 + bx + dx + offset[0], y0 + by + dy + offset[1]])
        errors.append(np.hypot(*(position - truth[k])))

    point = start.reshape(1, 1, 2).astype(np.float32)
    lk_errors = []
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.001)
    for k in range(1, len(frames)):
        point, status, _ = cv2.calcOpticalFlowPyrLK(frames[k - 1], frames[k], point, None, winSize=(21, 21), maxLevel=3, criteria=criteria)
        lk_errors.append(np.hypot(*(point[0, 0].astype(float) - truth[k])))

    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))
    print(json.dumps({
        "opencv": cv2.__version__,
        "frames": len(frames),
        "matchtemplate_parabola_rms_px": rms(errors),
        "pyramidal_lk_rms_px": rms(lk_errors),
    }))


if __name__ == "__main__":
    main(sys.argv[1])
