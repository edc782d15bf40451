//! Video input through the `ffmpeg` command-line tool (imageio-ffmpeg's static binary, found by
//! tests/reference/ffmpeg_exe.py): a lossless (FFV1, gray) encoding of a PNG sequence must give
//! exactly the tracks of the PNG folder, and times must come from the container's presentation
//! timestamps — here with a 0.12 s gap after frame 9 that a frame index / fps clock would miss.

use crate::common;

use shakeflow::io::parquet::read_table;
use shakeflow::table::ColumnData;

#[test]
fn video_frames_and_presentation_times() {
    let ffmpeg = common::run_python(&common::reference_script("ffmpeg_exe.py"), &[]).trim().to_string();
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    common::write_cpt_frames(&root.join("frames"), 20);
    // 25 fps, and every frame from the 10th on 3 frame periods (0.12 s) later.
    let encode = std::process::Command::new(&ffmpeg)
        .current_dir(root)
        .args(["-hide_banner", "-loglevel", "error", "-framerate", "25", "-i", "frames/f%04d.png"])
        .args(["-vf", "setpts='(N+if(gte(N,10),3,0))/(25*TB)'", "-fps_mode", "passthrough"])
        .args(["-c:v", "ffv1", "-pix_fmt", "gray", "clip.mkv"])
        .output()
        .unwrap();
    assert!(encode.status.success(), "{}", String::from_utf8_lossy(&encode.stderr));

    let track = |input: &str, output: &str, extra: &[&str]| {
        let mut args = vec!["stage", "cpt_track", "--input", input, "--output", output, "--set", "points=40,30"];
        args.extend(["--set", "window_px=12", "--set", "search_px=30"]);
        args.extend(extra);
        let out = common::shakeflow_env(&args, root, &[("SHAKEFLOW_FFMPEG", &ffmpeg)]);
        assert!(out.status.success(), "{}", common::stderr(&out));
        read_table(&root.join(output).join("tracks/data.parquet")).unwrap()
    };
    let from_png = track("frames", "png", &["--set", "fps=25"]);
    let from_video = track("clip.mkv", "video", &[]);
    for column in ["u_px", "v_px", "score"] {
        let png = from_png.f64_column(column).unwrap_or_else(|| panic!("no {column} column"));
        assert_eq!(png.len(), 20, "one row per frame and point");
        assert_eq!(Some(png), from_video.f64_column(column), "{column}: a lossless video decodes to the same pixels");
    }
    let time = from_video.f64_column("time_s").unwrap();
    assert_eq!(time.len(), 20);
    for (k, t) in time.iter().enumerate() {
        let expected = k as f64 / 25.0 + if k >= 10 { 0.12 } else { 0.0 };
        assert!((t - expected).abs() < 1e-9, "frame {k}: {t} s from the container, expected {expected} s");
    }
    assert!(matches!(&from_video.column("status").unwrap().data, ColumnData::Str(s) if s.iter().all(|s| s == "ok")));
    // `fps` overrides the container's clock.
    let by_index = track("clip.mkv", "video_fps", &["--set", "fps=25"]);
    assert!((by_index.f64_column("time_s").unwrap()[19] - 19.0 / 25.0).abs() < 1e-12);
}
