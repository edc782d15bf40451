#!/usr/bin/env python3
"""Prints the path of the static ffmpeg binary that the imageio-ffmpeg package ships.

The machine has no system ffmpeg; the video tests (tests/cpt_video.rs) use this one, both to
encode test videos and as shakeflow's decoder (SHAKEFLOW_FFMPEG).
"""
import imageio_ffmpeg

print(imageio_ffmpeg.get_ffmpeg_exe())
