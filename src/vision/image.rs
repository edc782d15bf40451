//! 8-bit grayscale frames and separable bicubic sampling (Keys, a = −0.5).
//!
//! Pixel (x, y) has its centre at integer coordinates (x, y), as in OpenCV.

#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    pub width: usize,
    pub height: usize,
    /// Row-major, `width * height` bytes.
    pub pixels: Vec<u8>,
}

impl GrayImage {
    pub fn new(width: usize, height: usize, pixels: Vec<u8>) -> GrayImage {
        assert_eq!(pixels.len(), width * height, "a {width}×{height} image has {} pixels", width * height);
        GrayImage { width, height, pixels }
    }

    pub fn row(&self, y: usize) -> &[u8] {
        &self.pixels[y * self.width..(y + 1) * self.width]
    }

    /// Whether integer pixel `(x, y)` is inside.
    pub fn contains(&self, x: i64, y: i64) -> bool {
        x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height
    }
}

/// Keys' cubic convolution weights for taps at −1, 0, 1, 2 around a sample at fraction `f`
/// (0 ≤ f < 1), and their derivatives with respect to the sample position.
pub fn cubic_weights(f: f64) -> ([f64; 4], [f64; 4]) {
    const A: f64 = -0.5;
    let near = |t: f64| ((A + 2.0) * t - (A + 3.0)) * t * t + 1.0;
    let far = |t: f64| ((A * t - 5.0 * A) * t + 8.0 * A) * t - 4.0 * A;
    let d_near = |t: f64| (3.0 * (A + 2.0) * t - 2.0 * (A + 3.0)) * t;
    let d_far = |t: f64| (3.0 * A * t - 10.0 * A) * t + 8.0 * A;
    let weights = [far(1.0 + f), near(f), near(1.0 - f), far(2.0 - f)];
    // d/df of w(|tap − f|): taps left of the sample move away as f grows, taps right come closer.
    let derivatives = [d_far(1.0 + f), d_near(f), -d_near(1.0 - f), -d_far(2.0 - f)];
    (weights, derivatives)
}

/// A `size × size` patch of `image` whose pixel (0, 0) sits at real position `origin`, with its
/// x and y derivatives, by separable bicubic interpolation. None when the taps leave the image.
pub struct Patch {
    pub size: usize,
    pub values: Vec<f64>,
    pub dx: Vec<f64>,
    pub dy: Vec<f64>,
}

pub fn sample_patch(image: &GrayImage, origin: [f64; 2], size: usize, scratch: &mut Vec<f64>) -> Option<Patch> {
    let (ix, iy) = (origin[0].floor(), origin[1].floor());
    let (fx, fy) = (origin[0] - ix, origin[1] - iy);
    let (ix, iy) = (ix as i64, iy as i64);
    if ix < 1 || iy < 1 || ix + size as i64 + 2 > image.width as i64 || iy + size as i64 + 2 > image.height as i64 {
        return None;
    }
    let (wx, dwx) = cubic_weights(fx);
    let (wy, dwy) = cubic_weights(fy);
    let rows = size + 3;
    // Horizontal pass: value and x-derivative for every row the vertical taps need.
    scratch.clear();
    scratch.resize(2 * rows * size, 0.0);
    let (h, hd) = scratch.split_at_mut(rows * size);
    for r in 0..rows {
        let row = image.row((iy - 1) as usize + r);
        let base = (ix - 1) as usize;
        for x in 0..size {
            let p = &row[base + x..base + x + 4];
            let (a, b, c, d) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]), f64::from(p[3]));
            h[r * size + x] = wx[0] * a + wx[1] * b + wx[2] * c + wx[3] * d;
            hd[r * size + x] = dwx[0] * a + dwx[1] * b + dwx[2] * c + dwx[3] * d;
        }
    }
    let n = size * size;
    let (mut values, mut dx, mut dy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for y in 0..size {
        for x in 0..size {
            let (mut v, mut gx, mut gy) = (0.0, 0.0, 0.0);
            for k in 0..4 {
                let i = (y + k) * size + x;
                v += wy[k] * h[i];
                gx += wy[k] * hd[i];
                gy += dwy[k] * h[i];
            }
            values[y * size + x] = v;
            dx[y * size + x] = gx;
            dy[y * size + x] = gy;
        }
    }
    Some(Patch { size, values, dx, dy })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_weights_sum_to_one_and_reproduce_linear_ramps() {
        for f in [0.0, 0.25, 0.5, 0.9] {
            let (w, d) = cubic_weights(f);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            // Sampling x itself at taps −1..2 gives f; its derivative is 1.
            let taps = [-1.0, 0.0, 1.0, 2.0];
            assert!((w.iter().zip(taps).map(|(w, t)| w * t).sum::<f64>() - f).abs() < 1e-14);
            assert!((d.iter().zip(taps).map(|(w, t)| w * t).sum::<f64>() - 1.0).abs() < 1e-14);
            assert!(d.iter().sum::<f64>().abs() < 1e-14);
        }
    }

    #[test]
    fn patch_of_a_ramp_is_exact() {
        let (w, h) = (40, 30);
        let pixels: Vec<u8> = (0..w * h).map(|i| (2 * (i % w) + 3 * (i / w)) as u8).collect();
        let image = GrayImage::new(w, h, pixels);
        let mut scratch = Vec::new();
        let patch = sample_patch(&image, [5.3, 4.6], 10, &mut scratch).unwrap();
        for y in 0..10 {
            for x in 0..10 {
                let expected = 2.0 * (5.3 + x as f64) + 3.0 * (4.6 + y as f64);
                assert!((patch.values[y * 10 + x] - expected).abs() < 1e-9);
                assert!((patch.dx[y * 10 + x] - 2.0).abs() < 1e-9 && (patch.dy[y * 10 + x] - 3.0).abs() < 1e-9);
            }
        }
        assert!(sample_patch(&image, [0.5, 4.0], 10, &mut scratch).is_none());
        assert!(sample_patch(&image, [29.0, 4.0], 10, &mut scratch).is_none());
    }
}
