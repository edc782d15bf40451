//! Exhaustive template matching: zero-mean normalised cross-correlation (ZNCC, the default: it
//! ignores gain and offset changes of the lighting) and the study's sum of squared differences
//! (Eq. 5), for every integer offset of an m × m template inside a search region.
//!
//! Both scores come from one integer cross-correlation Σ T·I per offset plus window sums Σ I and
//! Σ I² from integral images, so every score is computed from exact integers: the result is the
//! same on every machine whichever kernel runs. The correlation kernel is chosen at run time:
//! AVX-512 VNNI (u8 × i8, four products per lane), AVX2 (`vpmaddwd` on i16), or portable code.

use super::image::GrayImage;

/// Which similarity decides the best integer offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Score {
    /// Zero-mean normalised cross-correlation, in [−1, 1]; higher is better.
    Zncc,
    /// Sum of squared differences (the study's ‖W_t − W_t+1‖²); lower is better.
    Ssd,
}

/// The correlation kernels; all give identical integers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    Portable,
    Avx2,
    Vnni,
}

impl Kernel {
    /// The fastest kernel this processor runs.
    pub fn best() -> Kernel {
        *Kernel::available().last().expect("the portable kernel is always available")
    }

    /// Kernels this processor runs, slowest first.
    pub fn available() -> Vec<Kernel> {
        let mut out = vec![Kernel::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                out.push(Kernel::Avx2);
            }
            if std::arch::is_x86_feature_detected!("avx512vnni")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && std::arch::is_x86_feature_detected!("avx512bw")
            {
                out.push(Kernel::Vnni);
            }
        }
        out
    }

    pub fn name(self) -> &'static str {
        match self {
            Kernel::Portable => "portable",
            Kernel::Avx2 => "avx2",
            Kernel::Vnni => "avx512-vnni",
        }
    }
}

/// An m × m template prepared for every kernel.
#[derive(Debug, Clone)]
pub struct Template {
    pub size: usize,
    pub pixels: Vec<u8>,
    sum: i64,
    sum_sq: i64,
    /// Rows padded to `i16_stride` (a multiple of 8) with zeros.
    as_i16: Vec<i16>,
    i16_stride: usize,
    /// T − 128 as i8, rows padded to `i8_stride` (a multiple of 16) with zeros.
    as_i8: Vec<i8>,
    i8_stride: usize,
}

impl Template {
    pub fn new(size: usize, pixels: Vec<u8>) -> Template {
        assert_eq!(pixels.len(), size * size);
        let i16_stride = size.div_ceil(8) * 8;
        let i8_stride = size.div_ceil(16) * 16;
        let mut as_i16 = vec![0i16; size * i16_stride];
        let mut as_i8 = vec![0i8; size * i8_stride];
        for y in 0..size {
            for x in 0..size {
                let v = pixels[y * size + x];
                as_i16[y * i16_stride + x] = i16::from(v);
                as_i8[y * i8_stride + x] = (i16::from(v) - 128) as i8;
            }
        }
        let sum = pixels.iter().map(|&v| i64::from(v)).sum();
        let sum_sq = pixels.iter().map(|&v| i64::from(v) * i64::from(v)).sum();
        Template { size, pixels, sum, sum_sq, as_i16, i16_stride, as_i8, i8_stride }
    }

    /// Cuts the template whose top-left pixel is `(x, y)`; None when it leaves the image.
    pub fn cut(image: &GrayImage, x: i64, y: i64, size: usize) -> Option<Template> {
        if !image.contains(x, y) || !image.contains(x + size as i64 - 1, y + size as i64 - 1) {
            return None;
        }
        let mut pixels = Vec::with_capacity(size * size);
        for row in 0..size {
            let start = (y as usize + row) * image.width + x as usize;
            pixels.extend_from_slice(&image.pixels[start..start + size]);
        }
        Some(Template::new(size, pixels))
    }

    /// Standard deviation of the template's grey levels (its contrast).
    pub fn contrast(&self) -> f64 {
        let n = (self.size * self.size) as f64;
        let mean = self.sum as f64 / n;
        (self.sum_sq as f64 / n - mean * mean).max(0.0).sqrt()
    }
}

/// Scores of every integer offset; offset (0, 0) puts the template's top-left at `origin`.
#[derive(Debug, Clone)]
pub struct ScoreMap {
    pub origin: (i64, i64),
    pub cols: usize,
    pub rows: usize,
    pub zncc: Vec<f64>,
    pub ssd: Vec<f64>,
}

impl ScoreMap {
    /// Index of the best offset for `score`; ties go to the first in row-major order.
    pub fn best(&self, score: Score) -> usize {
        let values = match score {
            Score::Zncc => &self.zncc,
            Score::Ssd => &self.ssd,
        };
        let mut best = 0;
        for (i, &v) in values.iter().enumerate() {
            let better = match score {
                Score::Zncc => v > values[best],
                Score::Ssd => v < values[best],
            };
            if better {
                best = i;
            }
        }
        best
    }

    /// Sub-pixel peak near offset `index`: least-squares quadratic on its 3 × 3 neighbourhood,
    /// falling back to separate parabolas (clamped to ±0.5) when the fit has no maximum there.
    /// Returns the template's top-left position in frame pixels.
    pub fn subpixel_peak(&self, index: usize, score: Score) -> [f64; 2] {
        let (c, r) = (index % self.cols, index / self.cols);
        let integer = [self.origin.0 as f64 + c as f64, self.origin.1 as f64 + r as f64];
        if c == 0 || r == 0 || c + 1 == self.cols || r + 1 == self.rows {
            return integer;
        }
        let sign = if score == Score::Zncc { 1.0 } else { -1.0 };
        let values = if score == Score::Zncc { &self.zncc } else { &self.ssd };
        let s = |dx: i64, dy: i64| sign * values[(r as i64 + dy) as usize * self.cols + (c as i64 + dx) as usize];
        let (mut b, mut cc, mut e, mut x_pairs, mut x_mid, mut y_pairs, mut y_mid) =
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let v = s(dx, dy);
                b += dx as f64 * v;
                cc += dy as f64 * v;
                e += (dx * dy) as f64 * v;
                if dx == 0 {
                    x_mid += v
                } else {
                    x_pairs += v
                }
                if dy == 0 {
                    y_mid += v
                } else {
                    y_pairs += v
                }
            }
        }
        let (b, cc, e) = (b / 6.0, cc / 6.0, e / 4.0);
        let d = x_pairs / 6.0 - x_mid / 3.0;
        let f = y_pairs / 6.0 - y_mid / 3.0;
        let det = 4.0 * d * f - e * e;
        if d < 0.0 && det > 0.0 {
            let x = (-2.0 * f * b + e * cc) / det;
            let y = (-2.0 * d * cc + e * b) / det;
            if x.abs() <= 1.0 && y.abs() <= 1.0 {
                return [integer[0] + x, integer[1] + y];
            }
        }
        let parabola = |m: f64, z: f64, p: f64| {
            let curvature = m - 2.0 * z + p;
            if curvature < 0.0 {
                (0.5 * (m - p) / curvature).clamp(-0.5, 0.5)
            } else {
                0.0
            }
        };
        [integer[0] + parabola(s(-1, 0), s(0, 0), s(1, 0)), integer[1] + parabola(s(0, -1), s(0, 0), s(0, 1))]
    }
}

/// Reusable buffers: matching allocates nothing once they have grown.
#[derive(Default)]
pub struct Scratch {
    region_u8: Vec<u8>,
    region_i16: Vec<i16>,
    integral: Vec<i64>,
    integral_sq: Vec<i64>,
    correlation: Vec<i32>,
}

/// Scores `template` at every integer offset whose window lies both inside the square search
/// region of side `search` with top-left `top_left` and inside the image. None when no offset fits.
pub fn match_template(
    image: &GrayImage,
    template: &Template,
    top_left: (i64, i64),
    search: usize,
    kernel: Kernel,
    scratch: &mut Scratch,
) -> Option<ScoreMap> {
    let m = template.size as i64;
    let x0 = top_left.0.max(0);
    let y0 = top_left.1.max(0);
    let x1 = (top_left.0 + search as i64).min(image.width as i64);
    let y1 = (top_left.1 + search as i64).min(image.height as i64);
    let (w, h) = (x1 - x0, y1 - y0);
    if w < m || h < m {
        return None;
    }
    let (w, h) = (w as usize, h as usize);
    let (cols, rows) = (w - template.size + 1, h - template.size + 1);
    // The region, copied with zero padding on the right so kernels may read whole vectors.
    let stride = w + 64;
    let padded_rows = h + 1;
    scratch.region_u8.clear();
    scratch.region_u8.resize(stride * padded_rows, 0);
    for y in 0..h {
        let src = (y0 as usize + y) * image.width + x0 as usize;
        scratch.region_u8[y * stride..y * stride + w].copy_from_slice(&image.pixels[src..src + w]);
    }
    // Integral images of I and I² ((w + 1) × (h + 1), exact).
    let iw = w + 1;
    scratch.integral.clear();
    scratch.integral.resize(iw * (h + 1), 0);
    scratch.integral_sq.clear();
    scratch.integral_sq.resize(iw * (h + 1), 0);
    for y in 0..h {
        let (mut row_sum, mut row_sq) = (0i64, 0i64);
        for x in 0..w {
            let v = i64::from(scratch.region_u8[y * stride + x]);
            row_sum += v;
            row_sq += v * v;
            scratch.integral[(y + 1) * iw + x + 1] = scratch.integral[y * iw + x + 1] + row_sum;
            scratch.integral_sq[(y + 1) * iw + x + 1] = scratch.integral_sq[y * iw + x + 1] + row_sq;
        }
    }
    scratch.correlation.clear();
    scratch.correlation.resize(cols * rows, 0);
    correlate(template, kernel, cols, rows, stride, scratch);

    let n = (template.size * template.size) as i64;
    let t_var = n * template.sum_sq - template.sum * template.sum;
    let (mut zncc, mut ssd) = (vec![0.0; cols * rows], vec![0.0; cols * rows]);
    let m = template.size;
    for r in 0..rows {
        for c in 0..cols {
            let box_sum =
                |ii: &[i64]| ii[(r + m) * iw + c + m] - ii[r * iw + c + m] - ii[(r + m) * iw + c] + ii[r * iw + c];
            let s = box_sum(&scratch.integral);
            let s2 = box_sum(&scratch.integral_sq);
            let mut cross = i64::from(scratch.correlation[r * cols + c]);
            if kernel == Kernel::Vnni {
                cross += 128 * s;
            }
            let i_var = n * s2 - s * s;
            let numerator = n * cross - template.sum * s;
            let denominator = (t_var as f64 * i_var as f64).sqrt();
            zncc[r * cols + c] = if denominator > 0.0 { numerator as f64 / denominator } else { 0.0 };
            ssd[r * cols + c] = (template.sum_sq + s2 - 2 * cross) as f64;
        }
    }
    Some(ScoreMap { origin: (x0, y0), cols, rows, zncc, ssd })
}

fn correlate(template: &Template, kernel: Kernel, cols: usize, rows: usize, stride: usize, scratch: &mut Scratch) {
    match kernel {
        Kernel::Portable => portable(template, &scratch.region_u8, stride, cols, rows, &mut scratch.correlation),
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 => {
            assert!(std::arch::is_x86_feature_detected!("avx2"), "the AVX2 kernel needs AVX2");
            scratch.region_i16.clear();
            scratch.region_i16.extend(scratch.region_u8.iter().map(|&v| i16::from(v)));
            // SAFETY: AVX2 is present (checked above); the kernel's reads stay inside the padded
            // buffers (see its bounds assertions).
            unsafe { x86::avx2(template, &scratch.region_i16, stride, cols, rows, &mut scratch.correlation) }
        }
        #[cfg(target_arch = "x86_64")]
        Kernel::Vnni => {
            assert!(
                std::arch::is_x86_feature_detected!("avx512vnni") && std::arch::is_x86_feature_detected!("avx512vl"),
                "the VNNI kernel needs AVX-512 VNNI and VL"
            );
            // SAFETY: as above, for AVX-512 VNNI/VL/BW.
            unsafe { x86::vnni(template, &scratch.region_u8, stride, cols, rows, &mut scratch.correlation) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        _ => portable(template, &scratch.region_u8, stride, cols, rows, &mut scratch.correlation),
    }
}

fn portable(template: &Template, region: &[u8], stride: usize, cols: usize, rows: usize, out: &mut [i32]) {
    let m = template.size;
    for r in 0..rows {
        for c in 0..cols {
            let mut acc = 0i32;
            for ty in 0..m {
                let t = &template.pixels[ty * m..(ty + 1) * m];
                let s = &region[(r + ty) * stride + c..(r + ty) * stride + c + m];
                acc += t.iter().zip(s).map(|(&a, &b)| i32::from(a) * i32::from(b)).sum::<i32>();
            }
            out[r * cols + c] = acc;
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::Template;

    /// Four output rows at a time share each template row load; a template row is 16-lane
    /// chunks plus an optional 8-lane tail of `vpmaddwd` (i16 pairs → i32).
    #[target_feature(enable = "avx2")]
    pub unsafe fn avx2(t: &Template, region: &[i16], stride: usize, cols: usize, rows: usize, out: &mut [i32]) {
        let m = t.size;
        let ts = t.i16_stride;
        let (wide, tail) = (ts / 16, ts % 16 == 8);
        assert!(out.len() >= cols * rows);
        // Reads reach row rows + 3 + m − 1 at most when a block of four overruns `rows`: clamp instead.
        assert!(region.len() >= (rows - 1 + m) * stride + cols - 1 + ts);
        let tp = t.as_i16.as_ptr();
        let sp = region.as_ptr();
        let mut r = 0;
        while r < rows {
            let block = (rows - r).min(4);
            for c in 0..cols {
                let mut wide_acc = [_mm256_setzero_si256(); 4];
                let mut tail_acc = [_mm_setzero_si128(); 4];
                for ty in 0..m {
                    for k in 0..block {
                        let s = sp.add((r + k + ty) * stride + c);
                        let trow = tp.add(ty * ts);
                        for chunk in 0..wide {
                            let tv = _mm256_loadu_si256(trow.add(16 * chunk) as *const __m256i);
                            let sv = _mm256_loadu_si256(s.add(16 * chunk) as *const __m256i);
                            wide_acc[k] = _mm256_add_epi32(wide_acc[k], _mm256_madd_epi16(tv, sv));
                        }
                        if tail {
                            let tv = _mm_loadu_si128(trow.add(16 * wide) as *const __m128i);
                            let sv = _mm_loadu_si128(s.add(16 * wide) as *const __m128i);
                            tail_acc[k] = _mm_add_epi32(tail_acc[k], _mm_madd_epi16(tv, sv));
                        }
                    }
                }
                for k in 0..block {
                    let halves =
                        _mm_add_epi32(_mm256_castsi256_si128(wide_acc[k]), _mm256_extracti128_si256(wide_acc[k], 1));
                    out[(r + k) * cols + c] = horizontal_sum(_mm_add_epi32(halves, tail_acc[k]));
                }
            }
            r += 4;
        }
    }

    /// `vpdpbusd`: unsigned image bytes × signed (T − 128) bytes, four products summed per i32
    /// lane without intermediate saturation; the caller adds back 128 · Σ I.
    #[target_feature(enable = "avx512vnni,avx512vl,avx512bw,avx512f,avx2")]
    pub unsafe fn vnni(t: &Template, region: &[u8], stride: usize, cols: usize, rows: usize, out: &mut [i32]) {
        let m = t.size;
        let ts = t.i8_stride;
        let (wide, tail) = (ts / 32, ts % 32 == 16);
        assert!(out.len() >= cols * rows);
        assert!(region.len() >= (rows - 1 + m) * stride + cols - 1 + ts);
        let tp = t.as_i8.as_ptr();
        let sp = region.as_ptr();
        let mut r = 0;
        while r < rows {
            let block = (rows - r).min(4);
            for c in 0..cols {
                let mut wide_acc = [_mm256_setzero_si256(); 4];
                let mut tail_acc = [_mm_setzero_si128(); 4];
                for ty in 0..m {
                    for k in 0..block {
                        let s = sp.add((r + k + ty) * stride + c);
                        let trow = tp.add(ty * ts);
                        for chunk in 0..wide {
                            let tv = _mm256_loadu_si256(trow.add(32 * chunk) as *const __m256i);
                            let sv = _mm256_loadu_si256(s.add(32 * chunk) as *const __m256i);
                            wide_acc[k] = _mm256_dpbusd_epi32(wide_acc[k], sv, tv);
                        }
                        if tail {
                            let tv = _mm_loadu_si128(trow.add(32 * wide) as *const __m128i);
                            let sv = _mm_loadu_si128(s.add(32 * wide) as *const __m128i);
                            tail_acc[k] = _mm_dpbusd_epi32(tail_acc[k], sv, tv);
                        }
                    }
                }
                for k in 0..block {
                    let halves =
                        _mm_add_epi32(_mm256_castsi256_si128(wide_acc[k]), _mm256_extracti128_si256(wide_acc[k], 1));
                    out[(r + k) * cols + c] = horizontal_sum(_mm_add_epi32(halves, tail_acc[k]));
                }
            }
            r += 4;
        }
    }

    #[target_feature(enable = "avx2")]
    unsafe fn horizontal_sum(v: __m128i) -> i32 {
        let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b01_00_11_10));
        let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b10_11_00_01));
        _mm_cvtsi128_si32(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::synthetic_motion::SplitMix64;

    fn random_image(w: usize, h: usize, seed: u64) -> GrayImage {
        let mut rng = SplitMix64::new(seed);
        GrayImage::new(w, h, (0..w * h).map(|_| (rng.next_u64() >> 56) as u8).collect())
    }

    #[test]
    fn kernels_agree_exactly_and_find_the_template() {
        let image = random_image(90, 70, 1);
        for size in [7, 16, 20, 21, 33] {
            let template = Template::cut(&image, 30, 25, size).unwrap();
            let mut reference: Option<ScoreMap> = None;
            for kernel in Kernel::available() {
                let map = match_template(&image, &template, (12, 9), 60, kernel, &mut Scratch::default()).unwrap();
                let best = map.best(Score::Zncc);
                assert_eq!(
                    (map.origin.0 + (best % map.cols) as i64, map.origin.1 + (best / map.cols) as i64),
                    (30, 25)
                );
                assert!((map.zncc[best] - 1.0).abs() < 1e-12 && map.ssd[map.best(Score::Ssd)] == 0.0);
                if let Some(r) = &reference {
                    assert_eq!(r.zncc, map.zncc, "{kernel:?} differs for size {size}");
                    assert_eq!(r.ssd, map.ssd, "{kernel:?} differs for size {size}");
                }
                reference = Some(map);
            }
        }
    }

    #[test]
    fn zncc_ignores_gain_and_offset_ssd_does_not() {
        let image = random_image(80, 80, 2);
        let template = Template::cut(&image, 20, 20, 20).unwrap();
        let dimmer = GrayImage::new(80, 80, image.pixels.iter().map(|&v| (f64::from(v) * 0.5 + 40.0) as u8).collect());
        let map = match_template(&dimmer, &template, (5, 5), 50, Kernel::best(), &mut Scratch::default()).unwrap();
        let best = map.best(Score::Zncc);
        assert_eq!((best % map.cols, best / map.cols), (15, 15));
        assert!(map.zncc[best] > 0.999);
        assert!(map.ssd[best] > 1e5);
    }

    #[test]
    fn search_regions_are_clipped_to_the_image() {
        let image = random_image(50, 40, 3);
        let template = Template::cut(&image, 2, 3, 10).unwrap();
        let map = match_template(&image, &template, (-20, -20), 60, Kernel::best(), &mut Scratch::default()).unwrap();
        assert_eq!(map.origin, (0, 0));
        assert_eq!((map.cols, map.rows), (31, 31));
        assert!(match_template(&image, &template, (45, 0), 60, Kernel::best(), &mut Scratch::default()).is_none());
    }

    #[test]
    fn quadratic_peak_recovers_a_smooth_maximum() {
        let (px, py) = (0.3, -0.2);
        let zncc: Vec<f64> = (0..25)
            .map(|i| {
                let (x, y) = ((i % 5) as f64 - 2.0, (i / 5) as f64 - 2.0);
                1.0 - 0.1 * (x - px).powi(2) - 0.05 * (y - py).powi(2) + 0.02 * (x - px) * (y - py)
            })
            .collect();
        let map = ScoreMap { origin: (10, 20), cols: 5, rows: 5, ssd: zncc.iter().map(|v| -v).collect(), zncc };
        for score in [Score::Zncc, Score::Ssd] {
            let [x, y] = map.subpixel_peak(map.best(score), score);
            assert!((x - 12.3).abs() < 1e-12 && (y - 21.8).abs() < 1e-12, "{x} {y}");
        }
    }
}
