//! Exhaustive template matching: zero-mean normalised cross-correlation (ZNCC, the default: it
//! ignores gain and offset changes of the lighting) and the study's sum of squared differences
//! (Eq. 5), for every integer offset of an m × m template inside a search region.
//!
//! Both scores come from one integer cross-correlation Σ T·I per offset plus window sums Σ I and
//! Σ I² (sliding sums), so every score is computed from exact integers: the result is the
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
    column_sum: Vec<i32>,
    column_sq: Vec<i32>,
    window_sum: Vec<i64>,
    window_sq: Vec<i64>,
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
    // Kernels compute four rows at a time and read whole vectors: pad below and to the right.
    let padded_rows = h + 4;
    scratch.region_u8.clear();
    scratch.region_u8.resize(stride * padded_rows, 0);
    for y in 0..h {
        let src = (y0 as usize + y) * image.width + x0 as usize;
        scratch.region_u8[y * stride..y * stride + w].copy_from_slice(&image.pixels[src..src + w]);
    }
    // Σ I and Σ I² of every window, exactly: column sums over m rows slide down, a running sum
    // of them slides across.
    let m = template.size;
    let region = &scratch.region_u8;
    let (columns, columns_sq) = (&mut scratch.column_sum, &mut scratch.column_sq);
    columns.clear();
    columns.resize(w, 0);
    columns_sq.clear();
    columns_sq.resize(w, 0);
    // Column sums fit in i32 (m ≤ 200: 200 · 255² < 2³¹), which vectorises twice as wide.
    let add_row = |columns: &mut [i32], columns_sq: &mut [i32], y: usize, sign: i32| {
        for ((c, q), &v) in columns.iter_mut().zip(columns_sq.iter_mut()).zip(&region[y * stride..y * stride + w]) {
            let v = i32::from(v);
            *c += sign * v;
            *q += sign * v * v;
        }
    };
    for y in 0..m {
        add_row(columns, columns_sq, y, 1);
    }
    scratch.window_sum.clear();
    scratch.window_sum.resize(cols * rows, 0);
    scratch.window_sq.clear();
    scratch.window_sq.resize(cols * rows, 0);
    for r in 0..rows {
        if r > 0 {
            add_row(columns, columns_sq, r - 1, -1);
            add_row(columns, columns_sq, r + m - 1, 1);
        }
        let (mut sum, mut sq): (i64, i64) =
            (columns[..m].iter().map(|&v| i64::from(v)).sum(), columns_sq[..m].iter().map(|&v| i64::from(v)).sum());
        let sums = &mut scratch.window_sum[r * cols..(r + 1) * cols];
        let squares = &mut scratch.window_sq[r * cols..(r + 1) * cols];
        sums[0] = sum;
        squares[0] = sq;
        for c in 1..cols {
            sum += i64::from(columns[c + m - 1] - columns[c - 1]);
            sq += i64::from(columns_sq[c + m - 1] - columns_sq[c - 1]);
            sums[c] = sum;
            squares[c] = sq;
        }
    }
    scratch.correlation.clear();
    scratch.correlation.resize(cols * rows, 0);
    correlate(template, kernel, cols, rows, stride, scratch);

    // In f64 from here: every integer below stays under 2⁵³ (m ≤ 200), so the arithmetic is
    // still exact until the square root and the division, which IEEE rounds the same everywhere.
    let n = (m * m) as f64;
    let (t_sum, t_sum_sq) = (template.sum as f64, template.sum_sq as f64);
    let t_var = n * t_sum_sq - t_sum * t_sum;
    // VNNI correlates with T − 128: add back 128 Σ I.
    let offset = if kernel == Kernel::Vnni { 128.0 } else { 0.0 };
    let (mut zncc, mut ssd) = (vec![0.0; cols * rows], vec![0.0; cols * rows]);
    let windows = scratch.window_sum.iter().zip(&scratch.window_sq);
    for (((z, q), &correlation), (&s, &s2)) in
        zncc.iter_mut().zip(ssd.iter_mut()).zip(&scratch.correlation).zip(windows)
    {
        let (s, s2) = (s as f64, s2 as f64);
        let cross = f64::from(correlation) + offset * s;
        let denominator = (t_var * (n * s2 - s * s)).sqrt();
        *z = if denominator > 0.0 { (n * cross - t_sum * s) / denominator } else { 0.0 };
        *q = t_sum_sq + s2 - 2.0 * cross;
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
            // SAFETY: AVX2 is present (checked above); the region has 4 padding rows below and
            // 64 values of padding right of every row, which covers every read (see `avx2`).
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

    use super::{portable, Template};

    /// Dispatches on the template's row width in vectors, so the inner loops have constant trip
    /// counts; templates wider than these (over 56 px) take the portable kernel.
    ///
    /// # Safety
    /// AVX2 must be present; `region` must hold `rows + m + 3` rows of `stride` values, each row
    /// readable `cols + 16` values past its last offset (the caller pads it).
    pub unsafe fn avx2(t: &Template, region: &[i16], stride: usize, cols: usize, rows: usize, out: &mut [i32]) {
        assert!(out.len() >= cols * rows && region.len() >= (rows + t.size + 3) * stride);
        match (t.i16_stride / 16, t.i16_stride % 16 == 8) {
            (0, _) => avx2_rows::<0, true>(t, region, stride, cols, rows, out),
            (1, false) => avx2_rows::<1, false>(t, region, stride, cols, rows, out),
            (1, true) => avx2_rows::<1, true>(t, region, stride, cols, rows, out),
            (2, false) => avx2_rows::<2, false>(t, region, stride, cols, rows, out),
            (2, true) => avx2_rows::<2, true>(t, region, stride, cols, rows, out),
            (3, false) => avx2_rows::<3, false>(t, region, stride, cols, rows, out),
            (3, true) => avx2_rows::<3, true>(t, region, stride, cols, rows, out),
            _ => {
                let bytes: Vec<u8> = region.iter().map(|&v| v as u8).collect();
                portable(t, &bytes, stride, cols, rows, out)
            }
        }
    }

    /// Four output rows at a time share each template row, loaded once into registers; a row is
    /// WIDE 16-lane chunks plus (TAIL) an 8-lane chunk of `vpmaddwd` (i16 pairs → i32 sums).
    #[target_feature(enable = "avx2")]
    unsafe fn avx2_rows<const WIDE: usize, const TAIL: bool>(
        t: &Template,
        region: &[i16],
        stride: usize,
        cols: usize,
        rows: usize,
        out: &mut [i32],
    ) {
        let (m, ts) = (t.size, t.i16_stride);
        let (tp, sp) = (t.as_i16.as_ptr(), region.as_ptr());
        let mut r = 0;
        while r < rows {
            for c in 0..cols {
                let mut wide_acc = [_mm256_setzero_si256(); 4];
                let mut tail_acc = [_mm_setzero_si128(); 4];
                for ty in 0..m {
                    let trow = tp.add(ty * ts);
                    let mut tw = [_mm256_setzero_si256(); 3];
                    for (chunk, v) in tw.iter_mut().enumerate().take(WIDE) {
                        *v = _mm256_loadu_si256(trow.add(16 * chunk) as *const __m256i);
                    }
                    let tt =
                        if TAIL { _mm_loadu_si128(trow.add(16 * WIDE) as *const __m128i) } else { _mm_setzero_si128() };
                    for k in 0..4 {
                        let s = sp.add((r + k + ty) * stride + c);
                        for (chunk, tv) in tw.iter().enumerate().take(WIDE) {
                            let sv = _mm256_loadu_si256(s.add(16 * chunk) as *const __m256i);
                            wide_acc[k] = _mm256_add_epi32(wide_acc[k], _mm256_madd_epi16(*tv, sv));
                        }
                        if TAIL {
                            let sv = _mm_loadu_si128(s.add(16 * WIDE) as *const __m128i);
                            tail_acc[k] = _mm_add_epi32(tail_acc[k], _mm_madd_epi16(tt, sv));
                        }
                    }
                }
                // Rows past the last (a partial block of four) were computed on padding: dropped.
                for k in 0..(rows - r).min(4) {
                    out[(r + k) * cols + c] = reduce(wide_acc[k], tail_acc[k]);
                }
            }
            r += 4;
        }
    }

    /// # Safety
    /// AVX-512 VNNI, VL and BW must be present; `region` padded as for [`avx2`].
    pub unsafe fn vnni(t: &Template, region: &[u8], stride: usize, cols: usize, rows: usize, out: &mut [i32]) {
        assert!(out.len() >= cols * rows && region.len() >= (rows + t.size + 3) * stride);
        match (t.i8_stride / 32, t.i8_stride % 32 == 16) {
            (0, _) => vnni_rows::<0, true>(t, region, stride, cols, rows, out),
            (1, false) => vnni_rows::<1, false>(t, region, stride, cols, rows, out),
            (1, true) => vnni_rows::<1, true>(t, region, stride, cols, rows, out),
            (2, false) => vnni_rows::<2, false>(t, region, stride, cols, rows, out),
            (2, true) => vnni_rows::<2, true>(t, region, stride, cols, rows, out),
            (3, false) => vnni_rows::<3, false>(t, region, stride, cols, rows, out),
            (3, true) => vnni_rows::<3, true>(t, region, stride, cols, rows, out),
            _ => portable(t, region, stride, cols, rows, out),
        }
    }

    /// `vpdpbusd`: unsigned image bytes × signed (T − 128) bytes, four products summed per i32
    /// lane without intermediate saturation; the caller adds back 128 · Σ I.
    #[target_feature(enable = "avx512vnni,avx512vl,avx512bw,avx512f,avx2")]
    unsafe fn vnni_rows<const WIDE: usize, const TAIL: bool>(
        t: &Template,
        region: &[u8],
        stride: usize,
        cols: usize,
        rows: usize,
        out: &mut [i32],
    ) {
        let (m, ts) = (t.size, t.i8_stride);
        let (tp, sp) = (t.as_i8.as_ptr(), region.as_ptr());
        let mut r = 0;
        while r < rows {
            for c in 0..cols {
                let mut wide_acc = [_mm256_setzero_si256(); 4];
                let mut tail_acc = [_mm_setzero_si128(); 4];
                for ty in 0..m {
                    let trow = tp.add(ty * ts);
                    let mut tw = [_mm256_setzero_si256(); 3];
                    for (chunk, v) in tw.iter_mut().enumerate().take(WIDE) {
                        *v = _mm256_loadu_si256(trow.add(32 * chunk) as *const __m256i);
                    }
                    let tt =
                        if TAIL { _mm_loadu_si128(trow.add(32 * WIDE) as *const __m128i) } else { _mm_setzero_si128() };
                    for k in 0..4 {
                        let s = sp.add((r + k + ty) * stride + c);
                        for (chunk, tv) in tw.iter().enumerate().take(WIDE) {
                            let sv = _mm256_loadu_si256(s.add(32 * chunk) as *const __m256i);
                            wide_acc[k] = _mm256_dpbusd_epi32(wide_acc[k], sv, *tv);
                        }
                        if TAIL {
                            let sv = _mm_loadu_si128(s.add(32 * WIDE) as *const __m128i);
                            tail_acc[k] = _mm_dpbusd_epi32(tail_acc[k], sv, tt);
                        }
                    }
                }
                for k in 0..(rows - r).min(4) {
                    out[(r + k) * cols + c] = reduce(wide_acc[k], tail_acc[k]);
                }
            }
            r += 4;
        }
    }

    #[target_feature(enable = "avx2")]
    unsafe fn reduce(wide: __m256i, tail: __m128i) -> i32 {
        let v = _mm_add_epi32(_mm_add_epi32(_mm256_castsi256_si128(wide), _mm256_extracti128_si256(wide, 1)), tail);
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
