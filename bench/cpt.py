"""`make bench` (third part): the camera projection technique, shakeflow vs OpenCV, in one run.

1. Per-window matching: random 60 x 60 windows of a smooth speckle image, each with a 20 x 20
   template cut from inside it (up to 15 px off centre) and re-noised. shakeflow's exhaustive
   integer ZNCC (examples/cpt_match.rs, every kernel this processor runs) against
   cv2.matchTemplate(TM_CCOEFF_NORMED): both compute the full 41 x 41 score map. Microseconds per
   window (median of --repeat), ratio OpenCV / shakeflow (above 1: shakeflow is faster), and how
   often the two pick the same best offset.
2. End to end at 1080p: --frames frames of a speckle scene in which four textured plates move by
   sub-pixel amounts (cv2.warpAffine, bicubic) plus 3 grey levels of noise, written as a PNG folder
   and as an H.264 MP4 (crf 18, imageio-ffmpeg's ffmpeg). shakeflow runs `shakeflow stage cpt_track`
   on each (decoding, 4 points, Parquet + MCAP + PNG figure written); the OpenCV script reads the
   same files (cv2.imread / cv2.VideoCapture + cvtColor) and, per point, matches the first frame's
   template over a 60 px window around the last position (matchTemplate + minMaxLoc + parabola),
   writing a CSV. Frames per second over the whole process (start to exit), peak memory, ratios
   OpenCV / shakeflow for time (above 1: shakeflow is faster) and memory (above 1: leaner).
"""
import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile

import cv2
import imageio_ffmpeg
import numpy as np

HERE = pathlib.Path(__file__).resolve().parent


def measure(cmd):
    """Wall time and peak memory of `cmd`, measured from a fresh, small Python process: a child's
    peak RSS counts the image it was forked from, and this script holds hundreds of MB of frames."""
    code = f"import json, sys; sys.path.insert(0, {str(HERE)!r}); from load_baseline import measure; print(json.dumps(measure({cmd!r})))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return tuple(json.loads(out.stdout))

WINDOW, TEMPLATE = 60, 20
WIDTH, HEIGHT = 1920, 1080
PLATES = [(500, 350), (900, 600), (1300, 400), (1500, 800)]  # plate centres (px); points sit there
PLATE = 240

OPENCV_TRACKER = r'''
import csv, glob, os, sys
import cv2, numpy as np
source, out, points = sys.argv[1], sys.argv[2], [tuple(map(float, p.split(","))) for p in sys.argv[3].split(";")]
M, R = 20, 20
if os.path.isdir(source):
    files = sorted(glob.glob(os.path.join(source, "*.png")))
    frames = (cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in files)
else:
    capture = cv2.VideoCapture(source)
    def frames_of(capture):
        while True:
            ok, frame = capture.read()
            if not ok:
                return
            yield cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    frames = frames_of(capture)
def parabola(a, b, c):
    d = a - 2.0 * b + c
    return 0.5 * (a - c) / d if d < 0 else 0.0
first = next(frames)
state = []
for u, v in points:
    x, y = int(round(u - (M - 1) / 2)), int(round(v - (M - 1) / 2))
    state.append([first[y:y + M, x:x + M].copy(), u - x, v - y, u, v])
rows = []
for k, frame in enumerate(frames, start=1):
    for i, s in enumerate(state):
        template, ox, oy, u, v = s
        x0, y0 = int(round(u - ox)) - R, int(round(v - oy)) - R
        scores = cv2.matchTemplate(frame[y0:y0 + M + 2 * R, x0:x0 + M + 2 * R], template, cv2.TM_CCOEFF_NORMED)
        _, best, _, (bx, by) = cv2.minMaxLoc(scores)
        dx = parabola(scores[by, bx - 1], scores[by, bx], scores[by, bx + 1]) if 0 < bx < scores.shape[1] - 1 else 0.0
        dy = parabola(scores[by - 1, bx], scores[by, bx], scores[by + 1, bx]) if 0 < by < scores.shape[0] - 1 else 0.0
        s[3], s[4] = x0 + bx + dx + ox, y0 + by + dy + oy
        rows.append((k, i, s[3], s[4], best))
with open(out, "w", newline="") as fh:
    csv.writer(fh).writerows(rows)
'''


def speckle(rng, height, width, grain):
    noise = rng.uniform(0, 255, (height, width)).astype(np.float32)
    image = cv2.GaussianBlur(noise, (0, 0), grain)
    image = (image - image.mean()) / image.std()
    return np.clip(128 + 45 * image, 0, 255).astype(np.float32)


def per_window(args, tmp):
    rng = np.random.default_rng(7)
    count = args.windows
    image = speckle(rng, 2000, 2000, 1.5)
    windows, templates = [], []
    for _ in range(count):
        x, y = rng.integers(0, 2000 - WINDOW, size=2)
        window = image[y:y + WINDOW, x:x + WINDOW]
        tx, ty = rng.integers(WINDOW // 2 - TEMPLATE // 2 - 15, WINDOW // 2 - TEMPLATE // 2 + 16, size=2)
        template = window[ty:ty + TEMPLATE, tx:tx + TEMPLATE] + rng.normal(0, 3, (TEMPLATE, TEMPLATE))
        windows.append(np.clip(window + rng.normal(0, 3, window.shape), 0, 255).round().astype(np.uint8))
        templates.append(np.clip(template, 0, 255).round().astype(np.uint8))
    path = tmp / "windows.bin"
    path.write_bytes(b"".join(w.tobytes() for w in windows) + b"".join(t.tobytes() for t in templates))

    import time
    ours = []
    for _ in range(args.repeat):
        out = subprocess.run([args.matcher, str(path), str(count), str(WINDOW), str(TEMPLATE), "5"], check=True, capture_output=True, text=True)
        ours.append(json.loads(out.stdout))
    kernels = {k: statistics.median(o["us_per_window"][k] for o in ours) for k in ours[0]["us_per_window"]}
    cv_times = []
    for _ in range(args.repeat):
        started = time.perf_counter()
        for _ in range(5):
            for w, t in zip(windows, templates):
                cv2.matchTemplate(w, t, cv2.TM_CCOEFF_NORMED)
        cv_times.append((time.perf_counter() - started) * 1e6 / (5 * count))
    cv_us = statistics.median(cv_times)
    cv_peaks = [cv2.minMaxLoc(cv2.matchTemplate(w, t, cv2.TM_CCOEFF_NORMED))[3] for w, t in zip(windows, templates)]
    same = sum(tuple(p) == tuple(q) for p, q in zip(ours[0]["peaks"], cv_peaks))
    print(f"per-window matching: {TEMPLATE} px template over a {WINDOW} px window (41 x 41 ZNCC map), {count} windows, median of {args.repeat}")
    print(f"{'':34}{'us/window':>10}{'ratio':>8}")
    print(f"{'OpenCV ' + cv2.__version__ + ' matchTemplate':34}{cv_us:>10.2f}{1.0:>8.2f}")
    for kernel, us in kernels.items():
        marker = " (used)" if kernel == ours[0]["best_kernel"] else ""
        print(f"{'shakeflow ' + kernel + marker:34}{us:>10.2f}{cv_us / us:>8.2f}")
    print(f"same best offset as OpenCV in {same} of {count} windows")
    print()


def make_sequence(args, tmp):
    rng = np.random.default_rng(11)
    background = speckle(rng, HEIGHT, WIDTH, 2.0)
    textures = [speckle(rng, PLATE + 80, PLATE + 80, 1.5) for _ in PLATES]
    folder = tmp / "frames"
    folder.mkdir()
    video = tmp / "clip.mp4"
    encoder = subprocess.Popen(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray",
         "-s", f"{WIDTH}x{HEIGHT}", "-r", "30", "-i", "pipe:0", "-c:v", "libx264", "-preset", "veryfast", "-crf", "18",
         "-pix_fmt", "yuv420p", str(video)],
        stdin=subprocess.PIPE,
    )
    for k in range(args.frames):
        frame = background.copy()
        for i, ((cx, cy), texture) in enumerate(zip(PLATES, textures)):
            dx = 12 * np.sin(2 * np.pi * k / (90 + 17 * i)) + 0.37 * k / 30
            dy = 8 * np.sin(2 * np.pi * k / (70 + 11 * i))
            shifted = cv2.warpAffine(texture, np.float32([[1, 0, dx], [0, 1, dy]]), texture.shape[::-1], flags=cv2.INTER_CUBIC)
            h = PLATE // 2
            frame[cy - h:cy + h, cx - h:cx + h] = shifted[40:40 + PLATE, 40:40 + PLATE]
        frame = np.clip(frame + rng.normal(0, 3, frame.shape), 0, 255).round().astype(np.uint8)
        cv2.imwrite(str(folder / f"frame_{k:05d}.png"), frame)
        encoder.stdin.write(frame.tobytes())
    encoder.stdin.close()
    if encoder.wait() != 0:
        sys.exit("ffmpeg could not encode the benchmark video")
    return folder, video


def end_to_end(args, tmp):
    folder, video = make_sequence(args, tmp)
    points = ";".join(f"{cx},{cy}" for cx, cy in PLATES)
    script = tmp / "opencv_tracker.py"
    script.write_text(OPENCV_TRACKER)
    os.environ["SHAKEFLOW_FFMPEG"] = imageio_ffmpeg.get_ffmpeg_exe()
    sides = {}
    for label, source, extra in (("PNG folder", folder, ["--set", "fps=30"]), ("H.264 MP4", video, [])):
        for name, cmd in (
            (f"shakeflow cpt_track, {label}", lambda n: [args.shakeflow, "stage", "cpt_track", "--input", str(source), "--output", str(tmp / f"out{n}"), "--set", f"points={points}", *extra]),
            (f"OpenCV script, {label}", lambda n: [sys.executable, str(script), str(source), str(tmp / f"cv{n}.csv"), points]),
        ):
            sides[name] = [measure(cmd(n)) for n in range(args.repeat)]
    print(f"end to end at {WIDTH}x{HEIGHT}: {args.frames} frames, {len(PLATES)} points, decoding included, median of {args.repeat} ({os.cpu_count()} cores)")
    print(f"{'':34}{'fps':>8}{'wall s':>9}{'peak MiB':>10}{'fps ratio':>11}{'mem ratio':>11}")
    for label in ("PNG folder", "H.264 MP4"):
        cv_wall = statistics.median(w for w, _ in sides[f"OpenCV script, {label}"])
        cv_mem = statistics.median(m for _, m in sides[f"OpenCV script, {label}"])
        for side in (f"OpenCV script, {label}", f"shakeflow cpt_track, {label}"):
            wall = statistics.median(w for w, _ in sides[side])
            mem = statistics.median(m for _, m in sides[side])
            print(f"{side:34}{args.frames / wall:>8.1f}{wall:>9.2f}{mem:>10.1f}{cv_wall / wall:>11.2f}{cv_mem / mem:>11.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--matcher", required=True, help="the examples/cpt_match binary")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--windows", type=int, default=2000)
    ap.add_argument("--frames", type=int, default=300)
    args = ap.parse_args()
    cv2.setNumThreads(os.cpu_count())
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        per_window(args, tmp)
        end_to_end(args, tmp)


if __name__ == "__main__":
    main()
