//! The camera model: a 3×4 projection P = K [R | t] (Eq. 1 of the study) plus optional radial
//! distortion k₁, k₂ applied in normalised coordinates, exactly as OpenCV's model without
//! tangential terms: x_d = x_n (1 + k₁ r² + k₂ r⁴), pixel = K x_d.
//!
//! P is kept scaled so that ‖(p₃₁, p₃₂, p₃₃)‖ = 1 with det(p₁..₃) > 0: the third row then gives the
//! depth of a point in front of the camera, in the world unit (mm).

use super::linalg::{self, Mat3, Vec3};

/// Pinhole intrinsics K = [[fx, skew, cx], [0, fy, cy], [0, 0, 1]], in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub skew: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    pub fn matrix(&self) -> Mat3 {
        [[self.fx, self.skew, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]]
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    /// World → camera rotation.
    pub rotation: Mat3,
    /// World → camera translation (world unit).
    pub translation: Vec3,
    pub k1: f64,
    pub k2: f64,
}

impl Camera {
    pub fn new(intrinsics: Intrinsics, rotation: Mat3, translation: Vec3, k1: f64, k2: f64) -> Camera {
        Camera { intrinsics, rotation, translation, k1, k2 }
    }

    /// A camera at `centre` looking at `target`, image up ≈ world +Z (the usual mounting).
    pub fn look_at(intrinsics: Intrinsics, centre: Vec3, target: Vec3, k1: f64, k2: f64) -> Camera {
        let forward = normalise([target[0] - centre[0], target[1] - centre[1], target[2] - centre[2]]);
        let right = normalise(linalg::cross3(&forward, &[0.0, 0.0, 1.0]));
        let down = linalg::cross3(&forward, &right);
        let rotation = [right, down, forward];
        let rc = linalg::mat3_vec(&rotation, &centre);
        Camera::new(intrinsics, rotation, [-rc[0], -rc[1], -rc[2]], k1, k2)
    }

    /// From a projection matrix (any scale or sign) and distortion coefficients; None when
    /// the left 3×3 block is singular (not a camera).
    pub fn from_projection(p: &[[f64; 4]; 3], k1: f64, k2: f64) -> Option<Camera> {
        let mut m: Mat3 = [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]);
        let mut p4 = [p[0][3], p[1][3], p[2][3]];
        let det = linalg::det3(&m);
        if !det.is_finite() || det.abs() < 1e-300 {
            return None;
        }
        if det < 0.0 {
            m = m.map(|row| row.map(|v| -v));
            p4 = p4.map(|v| -v);
        }
        let (k, rotation) = linalg::rq3(&m);
        let scale = k[2][2];
        let k = k.map(|row| row.map(|v| v / scale));
        let p4 = p4.map(|v| v / scale);
        let intrinsics = Intrinsics { fx: k[0][0], fy: k[1][1], skew: k[0][1], cx: k[0][2], cy: k[1][2] };
        let translation = linalg::mat3_vec(&linalg::inverse3(&k)?, &p4);
        Some(Camera::new(intrinsics, rotation, translation, k1, k2))
    }

    /// P = K [R | t], scaled so that ‖(p₃₁, p₃₂, p₃₃)‖ = 1 (R's rows are unit vectors).
    pub fn projection(&self) -> [[f64; 4]; 3] {
        let kr = linalg::mat3_mul(&self.intrinsics.matrix(), &self.rotation);
        let kt = linalg::mat3_vec(&self.intrinsics.matrix(), &self.translation);
        [0, 1, 2].map(|i| [kr[i][0], kr[i][1], kr[i][2], kt[i]])
    }

    /// Camera centre in world coordinates: −Rᵀ t.
    pub fn centre(&self) -> Vec3 {
        let c = linalg::mat3_vec(&linalg::transpose3(&self.rotation), &self.translation);
        c.map(|v| -v)
    }

    /// Pixel of a world point; None when the point is not in front of the camera.
    pub fn project(&self, world: &Vec3) -> Option<[f64; 2]> {
        let c = linalg::mat3_vec(&self.rotation, world);
        let c = [c[0] + self.translation[0], c[1] + self.translation[1], c[2] + self.translation[2]];
        if !(c[2] > 0.0) {
            return None;
        }
        Some(self.pixel_of_normalised(c[0] / c[2], c[1] / c[2]))
    }

    /// Distorts normalised coordinates and maps them through K.
    pub fn pixel_of_normalised(&self, x: f64, y: f64) -> [f64; 2] {
        let r2 = x * x + y * y;
        let d = 1.0 + self.k1 * r2 + self.k2 * r2 * r2;
        let (xd, yd) = (x * d, y * d);
        let k = &self.intrinsics;
        [k.fx * xd + k.skew * yd + k.cx, k.fy * yd + k.cy]
    }

    /// Undistorted normalised coordinates of a pixel (inverts the radial model by Newton's
    /// method); None beyond the radius where the model stops being monotonic.
    pub fn normalised_of_pixel(&self, u: f64, v: f64) -> Option<[f64; 2]> {
        let k = &self.intrinsics;
        let yd = (v - k.cy) / k.fy;
        let xd = (u - k.cx - k.skew * yd) / k.fx;
        if self.k1 == 0.0 && self.k2 == 0.0 {
            return Some([xd, yd]);
        }
        let rd = (xd * xd + yd * yd).sqrt();
        if rd == 0.0 {
            return Some([0.0, 0.0]);
        }
        let mut r = rd;
        for _ in 0..50 {
            let r2 = r * r;
            let f = r * (1.0 + self.k1 * r2 + self.k2 * r2 * r2) - rd;
            let df = 1.0 + 3.0 * self.k1 * r2 + 5.0 * self.k2 * r2 * r2;
            if !(df > 0.0) {
                return None;
            }
            let step = f / df;
            r -= step;
            if step.abs() <= 1e-15 * r.abs().max(1e-300) {
                break;
            }
        }
        let r2 = r * r;
        if !(r >= 0.0) || (1.0 + 3.0 * self.k1 * r2 + 5.0 * self.k2 * r2 * r2) <= 0.0 {
            return None;
        }
        Some([xd * r / rd, yd * r / rd])
    }

    /// The pixel an ideal pinhole camera (same P, no distortion) would have seen.
    pub fn undistort_pixel(&self, u: f64, v: f64) -> Option<[f64; 2]> {
        let [x, y] = self.normalised_of_pixel(u, v)?;
        let k = &self.intrinsics;
        Some([k.fx * x + k.skew * y + k.cx, k.fy * y + k.cy])
    }
}

fn normalise(v: Vec3) -> Vec3 {
    let n = linalg::norm3(&v);
    v.map(|x| x / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(k1: f64, k2: f64) -> Camera {
        let k = Intrinsics { fx: 1400.0, fy: 1395.0, skew: 0.5, cx: 955.0, cy: 545.0 };
        Camera::look_at(k, [500.0, -4000.0, 1800.0], [0.0, 300.0, 600.0], k1, k2)
    }

    #[test]
    fn projection_matrix_reproduces_pinhole_projection() {
        let cam = camera(0.0, 0.0);
        let p = cam.projection();
        assert!((p[2][0].powi(2) + p[2][1].powi(2) + p[2][2].powi(2) - 1.0).abs() < 1e-12);
        let x = [120.0, 250.0, 800.0];
        let h: Vec<f64> = (0..3).map(|i| p[i][0] * x[0] + p[i][1] * x[1] + p[i][2] * x[2] + p[i][3]).collect();
        let [u, v] = cam.project(&x).unwrap();
        assert!((h[0] / h[2] - u).abs() < 1e-9 && (h[1] / h[2] - v).abs() < 1e-9);
        assert!(h[2] > 0.0, "depth is positive in front of the camera");
        let back = Camera::from_projection(&p.map(|r| r.map(|v| -3.0 * v)), 0.0, 0.0).unwrap();
        assert!((back.intrinsics.fx - 1400.0).abs() < 1e-9 && (back.intrinsics.skew - 0.5).abs() < 1e-9);
        let c = cam.centre();
        assert!((c[0] - 500.0).abs() < 1e-9 && (c[1] + 4000.0).abs() < 1e-9 && (c[2] - 1800.0).abs() < 1e-9);
    }

    #[test]
    fn undistortion_inverts_distortion() {
        let cam = camera(-0.12, 0.01);
        for (x, y) in [(0.0, 0.0), (0.3, -0.2), (-0.6, 0.35), (0.01, 0.5)] {
            let [u, v] = cam.pixel_of_normalised(x, y);
            let [xb, yb] = cam.normalised_of_pixel(u, v).unwrap();
            assert!((xb - x).abs() < 1e-13 && (yb - y).abs() < 1e-13, "{x} {y} -> {xb} {yb}");
        }
    }
}
