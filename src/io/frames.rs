//! Image sequences as 8-bit grayscale frames: a folder of PNG/JPEG files (natural sort order,
//! decoded in parallel batches) or a video file decoded by the `ffmpeg` command-line tool
//! (frames piped as raw gray bytes, presentation times read from its `showinfo` filter).
//!
//! Colour frames become luma with OpenCV's fixed-point BT.601 weights, so both tools see the
//! same grey levels. JPEG decoding uses zune-jpeg's portable code path (no run-time SIMD choice),
//! keeping decoded pixels identical on every machine.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc;

use rayon::prelude::*;

use crate::error::UserError;
use crate::vision::image::GrayImage;

/// Environment variable naming the ffmpeg binary (default: `ffmpeg` on the PATH).
pub const FFMPEG_ENV: &str = "SHAKEFLOW_FFMPEG";
const IMAGE_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];
const VIDEO_EXTENSIONS: [&str; 8] = ["mp4", "mov", "avi", "mkv", "m4v", "mpg", "mpeg", "webm"];

pub struct Frame {
    pub index: usize,
    /// Presentation time from the container (video only), seconds from the first frame.
    pub pts_s: Option<f64>,
    pub image: GrayImage,
    /// What errors about this frame should name: the file, or the video and frame number.
    pub label: String,
}

/// Whether `path` looks like an image sequence this module reads (a folder or a video file).
pub fn is_frame_source(path: &Path) -> bool {
    path.is_dir() || is_video(path)
}

pub fn is_video(path: &Path) -> bool {
    extension(path).is_some_and(|e| VIDEO_EXTENSIONS.contains(&e.as_str()))
}

fn extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase)
}

pub enum FrameReader {
    Images { files: Vec<PathBuf>, next: usize, size: Option<(usize, usize)> },
    Video(Box<VideoReader>),
}

impl FrameReader {
    pub fn open(path: &Path) -> Result<FrameReader, UserError> {
        if path.is_dir() {
            let files = image_files(path)?;
            Ok(FrameReader::Images { files, next: 0, size: None })
        } else if is_video(path) {
            Ok(FrameReader::Video(Box::new(VideoReader::open(path)?)))
        } else {
            Err(UserError::new("not an image sequence")
                .in_file(path)
                .hint(format!("give a folder of PNG/JPEG frames or a video file ({})", VIDEO_EXTENSIONS.join(", "))))
        }
    }

    /// Up to `count` next frames (empty at the end); image files are decoded in parallel.
    pub fn next_batch(&mut self, count: usize) -> Result<Vec<Frame>, UserError> {
        match self {
            FrameReader::Images { files, next, size } => {
                let end = (*next + count).min(files.len());
                let start = *next;
                let frames: Vec<Frame> = files[start..end]
                    .par_iter()
                    .enumerate()
                    .map(|(k, path)| {
                        let image = decode_image(path)?;
                        Ok(Frame { index: start + k, pts_s: None, image, label: path.display().to_string() })
                    })
                    .collect::<Result<_, UserError>>()?;
                for frame in &frames {
                    let this = (frame.image.width, frame.image.height);
                    let expected = *size.get_or_insert(this);
                    if this != expected {
                        return Err(UserError::new(format!(
                            "frame is {}×{} but the sequence's first frame is {}×{}",
                            this.0, this.1, expected.0, expected.1
                        ))
                        .in_file(&files[frame.index])
                        .hint("all frames of a sequence must have the same size"));
                    }
                }
                *next = end;
                Ok(frames)
            }
            FrameReader::Video(video) => {
                let mut frames = Vec::with_capacity(count);
                while frames.len() < count {
                    match video.next_frame()? {
                        Some(frame) => frames.push(frame),
                        None => break,
                    }
                }
                Ok(frames)
            }
        }
    }
}

/// Image files of a folder in natural order (`f2.png` before `f10.png`).
fn image_files(dir: &Path) -> Result<Vec<PathBuf>, UserError> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| UserError::new(format!("cannot list the frames folder: {e}")).in_file(dir))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && extension(p).is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.as_str())))
        .collect();
    if files.is_empty() {
        return Err(UserError::new("the frames folder holds no PNG or JPEG file")
            .in_file(dir)
            .hint("frames are files ending in .png, .jpg or .jpeg, read in natural name order"));
    }
    files.sort_by(|a, b| {
        natural_cmp(
            &a.file_name().unwrap_or_default().to_string_lossy(),
            &b.file_name().unwrap_or_default().to_string_lossy(),
        )
    });
    Ok(files)
}

/// Compares names with digit runs as numbers, then as text (so the order is total).
fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    fn chunks(s: &str) -> Vec<(bool, &str)> {
        let mut out = Vec::new();
        let mut start = 0;
        let bytes = s.as_bytes();
        for i in 1..=bytes.len() {
            if i == bytes.len() || bytes[i].is_ascii_digit() != bytes[start].is_ascii_digit() {
                out.push((bytes[start].is_ascii_digit(), &s[start..i]));
                start = i;
            }
        }
        out
    }
    let (ca, cb) = (chunks(a), chunks(b));
    for (x, y) in ca.iter().zip(&cb) {
        let order = match (x, y) {
            ((true, p), (true, q)) => {
                let (p, q) = (p.trim_start_matches('0'), q.trim_start_matches('0'));
                p.len().cmp(&q.len()).then(p.cmp(q))
            }
            ((_, p), (_, q)) => p.cmp(q),
        };
        if order.is_ne() {
            return order;
        }
    }
    ca.len().cmp(&cb.len()).then(a.cmp(b))
}

/// Decodes one PNG or JPEG file to 8-bit gray.
pub fn decode_image(path: &Path) -> Result<GrayImage, UserError> {
    let bytes = std::fs::read(path).map_err(|e| UserError::new(format!("cannot read the frame: {e}")).in_file(path))?;
    let unreadable = |e: DecodeError| {
        UserError::new(format!("cannot decode the frame: {e}"))
            .in_file(path)
            .hint("the file may be truncated or not the image its extension says; re-export the frame")
    };
    if bytes.starts_with(b"\x89PNG") {
        decode_png(&bytes).map_err(unreadable)
    } else if bytes.starts_with(&[0xFF, 0xD8]) {
        decode_jpeg(&bytes).map_err(unreadable)
    } else {
        Err(unreadable(DecodeError::NotAnImage))
    }
}

/// OpenCV's fixed-point BT.601 luma (cvtColor RGB2GRAY).
fn luma(r: u8, g: u8, b: u8) -> u8 {
    ((u32::from(r) * 4899 + u32::from(g) * 9617 + u32::from(b) * 1868 + 8192) >> 14) as u8
}

/// Why a frame's bytes are no image.
#[derive(Debug, thiserror::Error)]
enum DecodeError {
    #[error("neither PNG nor JPEG data")]
    NotAnImage,
    #[error("{0}")]
    Png(#[from] png::DecodingError),
    #[error("palette PNG left unexpanded")]
    Palette,
    /// The JPEG decoder's error, as its `Debug` names it.
    #[error("{0}")]
    Jpeg(String),
    #[error("no JPEG header")]
    NoJpegHeader,
    #[error("decoded {got} {what} for a {width}×{height} {image}")]
    Size { got: usize, what: &'static str, width: usize, height: usize, image: &'static str },
}

fn decode_png(bytes: &[u8]) -> Result<GrayImage, DecodeError> {
    let mut decoder = png::Decoder::new(bytes);
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info()?;
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer)?;
    let (w, h) = (info.width as usize, info.height as usize);
    let data = &buffer[..info.buffer_size()];
    let pixels = match info.color_type {
        png::ColorType::Grayscale => data.to_vec(),
        png::ColorType::GrayscaleAlpha => data.chunks_exact(2).map(|p| p[0]).collect(),
        png::ColorType::Rgb => data.chunks_exact(3).map(|p| luma(p[0], p[1], p[2])).collect(),
        png::ColorType::Rgba => data.chunks_exact(4).map(|p| luma(p[0], p[1], p[2])).collect(),
        png::ColorType::Indexed => return Err(DecodeError::Palette),
    };
    if pixels.len() != w * h {
        return Err(DecodeError::Size { got: pixels.len(), what: "pixels", width: w, height: h, image: "image" });
    }
    Ok(GrayImage::new(w, h, pixels))
}

fn decode_jpeg(bytes: &[u8]) -> Result<GrayImage, DecodeError> {
    use zune_jpeg::zune_core::bytestream::ZCursor;
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::Luma);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    let pixels = decoder.decode().map_err(|e| DecodeError::Jpeg(format!("{e:?}")))?;
    let info = decoder.info().ok_or(DecodeError::NoJpegHeader)?;
    let (w, h) = (usize::from(info.width), usize::from(info.height));
    if pixels.len() != w * h {
        return Err(DecodeError::Size { got: pixels.len(), what: "bytes", width: w, height: h, image: "gray image" });
    }
    Ok(GrayImage::new(w, h, pixels))
}

/// What the ffmpeg stderr reader reports.
enum Note {
    Size(usize, usize),
    Pts(f64),
}

pub struct VideoReader {
    path: PathBuf,
    child: Child,
    stdout: ChildStdout,
    notes: mpsc::Receiver<Note>,
    log: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
    size: Option<(usize, usize)>,
    /// Presentation times that arrived before the frame size (ffmpeg logs the first frame's
    /// before it announces its output).
    early_pts: std::collections::VecDeque<f64>,
    next: usize,
    first_pts: Option<f64>,
}

fn ffmpeg_binary() -> PathBuf {
    std::env::var_os(FFMPEG_ENV).map(PathBuf::from).unwrap_or_else(|| PathBuf::from("ffmpeg"))
}

impl VideoReader {
    pub fn open(path: &Path) -> Result<VideoReader, UserError> {
        if !path.is_file() {
            return Err(UserError::new("the video file does not exist").in_file(path));
        }
        let binary = ffmpeg_binary();
        let mut child = Command::new(&binary)
            .args(["-hide_banner", "-nostdin", "-nostats", "-loglevel", "info", "-i"])
            .arg(path)
            .args(["-map", "0:v:0", "-vf", "showinfo", "-fps_mode", "passthrough", "-f", "rawvideo", "-pix_fmt", "gray", "pipe:1"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                let problem = if e.kind() == std::io::ErrorKind::NotFound {
                    format!("reading a video needs the `ffmpeg` command-line tool, which was not found (`{}`)", binary.display())
                } else {
                    format!("cannot start `{}`: {e}", binary.display())
                };
                UserError::new(problem).in_file(path).hint(format!(
                    "install ffmpeg (e.g. `apt-get install ffmpeg`), or set {FFMPEG_ENV} to an ffmpeg binary, or give a folder of PNG/JPEG frames instead"
                ))
            })?;
        let stdout = child.stdout.take().expect("stdout is piped");
        let stderr = child.stderr.take().expect("stderr is piped");
        let (sender, notes) = mpsc::channel();
        let log = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let log_writer = log.clone();
        std::thread::spawn(move || {
            let mut in_output = false;
            for line in BufReader::new(stderr).split(b'\n') {
                let Ok(line) = line else { break };
                let line = String::from_utf8_lossy(&line).trim_end_matches('\r').to_string();
                if line.starts_with("Output #0") {
                    in_output = true;
                } else if in_output && line.contains("Video:") {
                    if let Some((w, h)) = frame_size(&line) {
                        let _ = sender.send(Note::Size(w, h));
                    }
                    in_output = false;
                } else if let Some(pts) = line.split("pts_time:").nth(1) {
                    if line.contains("showinfo") {
                        if let Some(Ok(t)) = pts.split_whitespace().next().map(str::parse::<f64>) {
                            let _ = sender.send(Note::Pts(t));
                        }
                        continue;
                    }
                }
                let mut log = log_writer.lock().expect("log lock");
                log.push(line);
                if log.len() > 40 {
                    log.remove(0);
                }
            }
        });
        Ok(VideoReader {
            path: path.to_path_buf(),
            child,
            stdout,
            notes,
            log,
            size: None,
            early_pts: std::collections::VecDeque::new(),
            next: 0,
            first_pts: None,
        })
    }

    fn failure(&mut self, what: &str) -> UserError {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let log =
            self.log.lock().expect("log lock").iter().rev().take(6).rev().cloned().collect::<Vec<_>>().join("\n    ");
        UserError::new(format!("{what}; ffmpeg said:\n    {log}"))
            .in_file(&self.path)
            .hint("check that the file is a readable video (`ffmpeg -i FILE`), or extract its frames to PNG files")
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, UserError> {
        while self.size.is_none() {
            match self.notes.recv() {
                Ok(Note::Size(w, h)) => self.size = Some((w, h)),
                Ok(Note::Pts(t)) => self.early_pts.push_back(t),
                Err(_) => return Err(self.failure("ffmpeg could not decode the video")),
            }
        }
        let (w, h) = self.size.expect("set above");
        let mut pixels = vec![0u8; w * h];
        let mut filled = 0;
        while filled < pixels.len() {
            match self.stdout.read(&mut pixels[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) => return Err(self.failure(&format!("reading decoded frames failed: {e}"))),
            }
        }
        if filled == 0 {
            let status = self.child.wait().map_err(|e| UserError::new(format!("waiting for ffmpeg: {e}")))?;
            if !status.success() || self.next == 0 {
                return Err(self.failure("ffmpeg stopped with an error"));
            }
            return Ok(None);
        }
        if filled < pixels.len() {
            return Err(self.failure(&format!("frame {} ended after {filled} of {} bytes", self.next, pixels.len())));
        }
        let pts = loop {
            if let Some(t) = self.early_pts.pop_front() {
                break t;
            }
            match self.notes.recv() {
                Ok(Note::Pts(t)) => break t,
                Ok(Note::Size(..)) => continue,
                Err(_) => return Err(self.failure(&format!("no presentation time for frame {}", self.next))),
            }
        };
        let first = *self.first_pts.get_or_insert(pts);
        let frame = Frame {
            index: self.next,
            pts_s: Some(pts - first),
            image: GrayImage::new(w, h, pixels),
            label: format!("{} (frame {})", self.path.display(), self.next),
        };
        self.next += 1;
        Ok(Some(frame))
    }
}

impl Drop for VideoReader {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `..., gray, 640x480, ...` → (640, 480).
fn frame_size(line: &str) -> Option<(usize, usize)> {
    line.split([',', ' ']).find_map(|token| {
        let (w, h) = token.split_once('x')?;
        Some((w.parse().ok()?, h.parse().ok()?))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The messages users read (after "cannot decode the frame: "), as they were when these
    /// errors were strings.
    #[test]
    fn decode_errors_say_what_was_wrong() {
        assert_eq!(DecodeError::NotAnImage.to_string(), "neither PNG nor JPEG data");
        assert_eq!(DecodeError::Palette.to_string(), "palette PNG left unexpanded");
        assert_eq!(DecodeError::NoJpegHeader.to_string(), "no JPEG header");
        let size = DecodeError::Size { got: 5, what: "pixels", width: 2, height: 3, image: "image" };
        assert_eq!(size.to_string(), "decoded 5 pixels for a 2×3 image");
        let size = DecodeError::Size { got: 5, what: "bytes", width: 2, height: 3, image: "gray image" };
        assert_eq!(size.to_string(), "decoded 5 bytes for a 2×3 gray image");
        let truncated = decode_png(b"\x89PNG\r\n\x1a\n").unwrap_err();
        assert!(matches!(truncated, DecodeError::Png(_)), "{truncated:?}");
        assert!(matches!(decode_jpeg(&[0xFF, 0xD8]).unwrap_err(), DecodeError::Jpeg(_) | DecodeError::NoJpegHeader));
    }

    #[test]
    fn names_sort_naturally() {
        let mut names = vec!["f10.png", "f2.png", "f1.png", "f02.png", "a.png"];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(names, ["a.png", "f1.png", "f02.png", "f2.png", "f10.png"]);
    }

    #[test]
    fn ffmpeg_stream_lines_give_the_size() {
        let line =
            "  Stream #0:0: Video: rawvideo (Y800 / 0x30303859), gray, 1920x1080 [SAR 1:1 DAR 16:9], q=2-31, 30 fps";
        assert_eq!(frame_size(line), Some((1920, 1080)));
    }

    #[test]
    fn png_frames_decode_to_gray() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("f.png");
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, 3, 1);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().unwrap();
            w.write_image_data(&[255, 0, 0, 0, 255, 0, 10, 20, 30]).unwrap();
        }
        std::fs::write(&path, out).unwrap();
        let image = decode_image(&path).unwrap();
        assert_eq!(image.pixels, [76, 150, luma(10, 20, 30)]);
        std::fs::write(&path, b"\x89PNG broken").unwrap();
        let err = decode_image(&path).unwrap_err();
        assert!(err.to_string().contains("cannot decode the frame"), "{err}");
    }
}
