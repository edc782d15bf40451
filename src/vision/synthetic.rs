//! Synthetic frames with known sub-pixel motion, for validating the tracker: smooth random
//! speckle layers rendered at 8× and area-downsampled (each output pixel is the mean of its
//! 8 × 8 samples), then lighting (gain, offset, a spatial ramp), blur, an occluder, noise and
//! rounding to 8 bits. Layers move by multiples of 1/8 px, so the truth is exact.

use super::image::{cubic_weights, GrayImage};
use crate::signal::synthetic_motion::SplitMix64;

/// Samples per output pixel along each axis.
pub const SUPERSAMPLING: usize = 8;
/// How far (output px) a layer may move before its texture runs out.
pub const MARGIN: usize = 40;
/// Speckle grain: random grey levels on a grid of this pitch (output px), interpolated.
const GRAIN_PX: usize = 2;

/// One speckle texture at the supersampled resolution, as an integral image.
struct Texture {
    /// Side lengths in samples: (width + 2·MARGIN)·8 by (height + 2·MARGIN)·8.
    cols: usize,
    rows: usize,
    /// (cols + 1) × (rows + 1) running sums.
    integral: Vec<f64>,
    values: Vec<f32>,
}

impl Texture {
    fn new(width: usize, height: usize, seed: u64) -> Texture {
        let s = SUPERSAMPLING;
        let (cols, rows) = ((width + 2 * MARGIN) * s, (height + 2 * MARGIN) * s);
        let pitch = GRAIN_PX * s;
        let (gc, gr) = (cols / pitch + 4, rows / pitch + 4);
        let mut rng = SplitMix64::new(seed);
        let grid: Vec<f64> = (0..gc * gr).map(|_| rng.uniform(20.0, 235.0)).collect();
        // Separable bicubic interpolation of the grid: horizontal pass on grid rows, then vertical.
        let mut horizontal = vec![0.0; cols * gr];
        for x in 0..cols {
            let position = x as f64 / pitch as f64;
            let (i, f) = (position.floor() as usize + 1, position.fract());
            let (w, _) = cubic_weights(f);
            for r in 0..gr {
                horizontal[r * cols + x] = (0..4).map(|k| w[k] * grid[r * gc + i + k - 1]).sum();
            }
        }
        let mut values = vec![0.0f32; cols * rows];
        for y in 0..rows {
            let position = y as f64 / pitch as f64;
            let (i, f) = (position.floor() as usize + 1, position.fract());
            let (w, _) = cubic_weights(f);
            for x in 0..cols {
                let v: f64 = (0..4).map(|k| w[k] * horizontal[(i + k - 1) * cols + x]).sum();
                values[y * cols + x] = v as f32;
            }
        }
        let mut integral = vec![0.0; (cols + 1) * (rows + 1)];
        for y in 0..rows {
            let mut row = 0.0;
            for x in 0..cols {
                row += f64::from(values[y * cols + x]);
                integral[(y + 1) * (cols + 1) + x + 1] = integral[y * (cols + 1) + x + 1] + row;
            }
        }
        Texture { cols, rows, integral, values }
    }

    /// Mean of the 8 × 8 block whose top-left sample is (sx, sy).
    fn block_mean(&self, sx: usize, sy: usize) -> f64 {
        let s = SUPERSAMPLING;
        let w = self.cols + 1;
        let sum =
            self.integral[(sy + s) * w + sx + s] - self.integral[sy * w + sx + s] - self.integral[(sy + s) * w + sx]
                + self.integral[sy * w + sx];
        sum / (s * s) as f64
    }

    fn sample(&self, sx: usize, sy: usize) -> f64 {
        f64::from(self.values[sy.min(self.rows - 1) * self.cols + sx.min(self.cols - 1)])
    }
}

/// A textured layer: the whole frame (`rect` None) or a rectangle (x0, y0, x1, y1 in output px
/// at zero shift, multiples of 1/8), moved by `shift` (rounded to 1/8 px). Later layers cover
/// earlier ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layer {
    pub texture: usize,
    pub rect: Option<[f64; 4]>,
    pub shift: [f64; 2],
}

impl Layer {
    pub fn background(shift: [f64; 2]) -> Layer {
        Layer { texture: 0, rect: None, shift }
    }
}

pub fn quantise(v: f64) -> f64 {
    (v * SUPERSAMPLING as f64).round() / SUPERSAMPLING as f64
}

/// Per-frame photometric effects, applied in this order: gain and offset, a horizontal ramp,
/// Gaussian blur, an occluder, noise, rounding and clipping to 0..255.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Look {
    pub gain: f64,
    pub offset: f64,
    /// Grey levels added per pixel to the right of the centre.
    pub ramp_per_px: f64,
    pub blur_sigma_px: f64,
    /// Rectangle (x0, y0, x1, y1) painted with a flat grey level.
    pub occluder: Option<([f64; 4], f64)>,
    pub noise_sigma: f64,
}

impl Default for Look {
    fn default() -> Self {
        Look { gain: 1.0, offset: 0.0, ramp_per_px: 0.0, blur_sigma_px: 0.0, occluder: None, noise_sigma: 0.0 }
    }
}

/// A layer ready to render: its texture, its moved rectangle and its shift, in samples.
type Placed<'a> = (&'a Texture, Option<[i64; 4]>, [i64; 2]);

pub struct SpeckleScene {
    pub width: usize,
    pub height: usize,
    textures: Vec<Texture>,
}

impl SpeckleScene {
    /// A scene with `textures` independent speckle textures (layer.texture indexes them).
    pub fn with_textures(width: usize, height: usize, textures: usize, seed: u64) -> SpeckleScene {
        let textures = (0..textures as u64).map(|k| Texture::new(width, height, seed.wrapping_add(k * 7919))).collect();
        SpeckleScene { width, height, textures }
    }

    pub fn new(width: usize, height: usize, seed: u64) -> SpeckleScene {
        SpeckleScene::with_textures(width, height, 1, seed)
    }

    /// Frame `index` (it seeds the noise) of the layers under a `look`.
    pub fn render_with(&self, layers: &[Layer], look: &Look, index: u64) -> GrayImage {
        let s = SUPERSAMPLING as i64;
        let (w, h) = (self.width, self.height);
        let placed: Vec<Placed<'_>> = layers
            .iter()
            .map(|l| {
                let shift = l.shift.map(|v| (v * s as f64).round() as i64);
                assert!(
                    shift.iter().all(|v| v.abs() < (MARGIN as i64 - 2) * s),
                    "layer shift {:?} beyond the margin",
                    l.shift
                );
                // Sample-grid rectangle of the moved layer.
                let rect = l.rect.map(|r| {
                    let q = r.map(|v| (v * s as f64).round() as i64);
                    [q[0] + shift[0], q[1] + shift[1], q[2] + shift[0], q[3] + shift[1]]
                });
                (&self.textures[l.texture], rect, shift)
            })
            .collect();
        let margin = MARGIN as i64 * s;
        let mut image = vec![0.0f64; w * h];
        for y in 0..h {
            for x in 0..w {
                let (sx0, sy0) = (x as i64 * s, y as i64 * s);
                // The topmost layer covering the whole pixel; samples are mixed only when a
                // layer above it covers part of the pixel.
                let top = placed
                    .iter()
                    .rposition(|(_, rect, _)| {
                        rect.is_none_or(|r| sx0 >= r[0] && sy0 >= r[1] && sx0 + s <= r[2] && sy0 + s <= r[3])
                    })
                    .expect("the first layer covers the frame");
                let partial = placed[top + 1..].iter().any(|(_, rect, _)| {
                    rect.is_some_and(|r| sx0 < r[2] && sy0 < r[3] && sx0 + s > r[0] && sy0 + s > r[1])
                });
                image[y * w + x] = if !partial {
                    let (texture, _, shift) = placed[top];
                    texture.block_mean((sx0 + margin - shift[0]) as usize, (sy0 + margin - shift[1]) as usize)
                } else {
                    let mut sum = 0.0;
                    for sy in sy0..sy0 + s {
                        for sx in sx0..sx0 + s {
                            let (texture, _, shift) = placed
                                .iter()
                                .rev()
                                .find(|(_, rect, _)| {
                                    rect.is_none_or(|r| sx >= r[0] && sy >= r[1] && sx < r[2] && sy < r[3])
                                })
                                .expect("the first layer covers the frame");
                            sum += texture.sample((sx + margin - shift[0]) as usize, (sy + margin - shift[1]) as usize);
                        }
                    }
                    sum / (s * s) as f64
                };
            }
        }
        finish(image, w, h, look, index)
    }

    pub fn render(&self, layers: &[Layer], noise_sigma: f64, index: u64) -> GrayImage {
        self.render_with(layers, &Look { noise_sigma, ..Look::default() }, index)
    }
}

fn finish(mut image: Vec<f64>, w: usize, h: usize, look: &Look, index: u64) -> GrayImage {
    let centre = w as f64 / 2.0;
    for y in 0..h {
        for x in 0..w {
            let v = &mut image[y * w + x];
            *v = look.gain * *v + look.offset + look.ramp_per_px * (x as f64 - centre);
        }
    }
    if look.blur_sigma_px > 0.0 {
        image = gaussian_blur(&image, w, h, look.blur_sigma_px);
    }
    if let Some((r, grey)) = look.occluder {
        for y in 0..h {
            for x in 0..w {
                // Area coverage of the pixel [x − ½, x + ½) by the rectangle, for soft edges.
                let cover = |lo: f64, hi: f64, c: f64| (hi.min(c + 0.5) - lo.max(c - 0.5)).clamp(0.0, 1.0);
                let a = cover(r[0], r[2], x as f64) * cover(r[1], r[3], y as f64);
                let v = &mut image[y * w + x];
                *v = (1.0 - a) * *v + a * grey;
            }
        }
    }
    let mut rng = SplitMix64::new(0x5eed_0000 ^ index.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let pixels = image
        .iter()
        .map(|&v| {
            let noisy = v + if look.noise_sigma > 0.0 { look.noise_sigma * rng.normal() } else { 0.0 };
            noisy.round().clamp(0.0, 255.0) as u8
        })
        .collect();
    GrayImage::new(w, h, pixels)
}

fn gaussian_blur(image: &[f64], w: usize, h: usize, sigma: f64) -> Vec<f64> {
    let radius = (3.0 * sigma).ceil() as i64;
    let kernel: Vec<f64> = (-radius..=radius).map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp()).collect();
    let total: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / total).collect();
    let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
    let mut tmp = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            tmp[y * w + x] =
                kernel.iter().enumerate().map(|(k, c)| c * image[y * w + clamp(x as i64 + k as i64 - radius, w)]).sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] =
                kernel.iter().enumerate().map(|(k, c)| c * tmp[clamp(y as i64 + k as i64 - radius, h) * w + x]).sum();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shifting_by_whole_pixels_moves_the_image() {
        let scene = SpeckleScene::new(40, 30, 5);
        let a = scene.render(&[Layer::background([0.0, 0.0])], 0.0, 0);
        let b = scene.render(&[Layer::background([3.0, -2.0])], 0.0, 0);
        for y in 5..25 {
            for x in 5..30 {
                assert_eq!(a.pixels[y * 40 + x], b.pixels[(y - 2) * 40 + x + 3]);
            }
        }
        let std = {
            let m = a.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / a.pixels.len() as f64;
            (a.pixels.iter().map(|&v| (f64::from(v) - m).powi(2)).sum::<f64>() / a.pixels.len() as f64).sqrt()
        };
        assert!(std > 25.0, "the speckle has contrast: std {std}");
    }

    #[test]
    fn a_plate_layer_moves_alone() {
        let scene = SpeckleScene::with_textures(60, 40, 2, 9);
        let plate = |dx: f64| Layer { texture: 1, rect: Some([20.0, 10.0, 40.0, 30.0]), shift: [dx, 0.0] };
        let a = scene.render(&[Layer::background([0.0, 0.0]), plate(0.0)], 0.0, 0);
        let b = scene.render(&[Layer::background([0.0, 0.0]), plate(2.0)], 0.0, 0);
        assert_eq!(a.pixels[5 * 60 + 5], b.pixels[5 * 60 + 5], "background unchanged");
        assert_eq!(a.pixels[20 * 60 + 25], b.pixels[20 * 60 + 27], "plate moved by 2 px");
    }
}
