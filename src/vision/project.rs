//! From tracked pixels to 3D: back-projection onto a known plane aX + bY + cZ + d = 0 (the
//! study's Eq. 3 and Eq. 4), and the rigid motion of a unit from two of its points.

use super::camera::Camera;
use super::linalg::{self, Vec3};

/// A plane aX + bY + cZ + d = 0 (world unit, usually mm). Its normal (a, b, c) also orients
/// rotations measured in it (right-handed about the normal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: f64,
}

impl Plane {
    pub fn normal(&self) -> Vec3 {
        [self.a, self.b, self.c]
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum ProjectError {
    /// The ray meets the plane at less than the minimum angle (degrees).
    GrazingRay { angle_deg: f64 },
    /// The ray meets the plane behind the camera.
    BehindCamera,
    /// The pixel is beyond the radius where the distortion model can be inverted.
    OutsideDistortionModel,
}

impl std::fmt::Display for ProjectError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ProjectError::GrazingRay { angle_deg } => {
                write!(f, "the camera ray meets the plane at {angle_deg:.2}°, nearly parallel: the 3D position is not determined")
            }
            ProjectError::BehindCamera => write!(f, "the camera ray meets the plane behind the camera"),
            ProjectError::OutsideDistortionModel => {
                write!(f, "the pixel lies where the lens distortion model cannot be inverted")
            }
        }
    }
}

/// Eq. 4: the point of `plane` seen at pixel (u, v), after removing lens distortion. Rays that
/// meet the plane at less than `min_angle_deg` are refused (a pixel of error would move the
/// point by more than 1/sin(angle) pixels' worth along the plane).
pub fn backproject(camera: &Camera, pixel: [f64; 2], plane: &Plane, min_angle_deg: f64) -> Result<Vec3, ProjectError> {
    let [u, v] = camera.undistort_pixel(pixel[0], pixel[1]).ok_or(ProjectError::OutsideDistortionModel)?;
    let p = camera.projection();
    let m = [
        [p[0][0] - p[2][0] * u, p[0][1] - p[2][1] * u, p[0][2] - p[2][2] * u],
        [p[1][0] - p[2][0] * v, p[1][1] - p[2][1] * v, p[1][2] - p[2][2] * v],
        [plane.a, plane.b, plane.c],
    ];
    let rhs = [-(p[0][3] - p[2][3] * u), -(p[1][3] - p[2][3] * v), -plane.d];
    // The ray's direction, for the angle test: Rᵀ K⁻¹ (u, v, 1).
    let ray = {
        let k_inv = linalg::inverse3(&camera.intrinsics.matrix()).expect("K has a positive diagonal");
        linalg::mat3_vec(&linalg::transpose3(&camera.rotation), &linalg::mat3_vec(&k_inv, &[u, v, 1.0]))
    };
    let normal = plane.normal();
    let sine = linalg::dot3(&ray, &normal).abs() / (linalg::norm3(&ray) * linalg::norm3(&normal));
    let angle_deg = sine.clamp(0.0, 1.0).asin().to_degrees();
    if !(angle_deg >= min_angle_deg) {
        return Err(ProjectError::GrazingRay { angle_deg });
    }
    let inverse = linalg::inverse3(&m).ok_or(ProjectError::GrazingRay { angle_deg })?;
    let x = linalg::mat3_vec(&inverse, &rhs);
    let depth = p[2][0] * x[0] + p[2][1] * x[1] + p[2][2] * x[2] + p[2][3];
    if !(depth > 0.0) {
        return Err(ProjectError::BehindCamera);
    }
    Ok(x)
}

/// Rigid motion of a unit from two of its points on the plane, relative to the first sample
/// where both are known: translation of their midpoint and the rotation of the segment between
/// them about the plane normal (right-handed, radians, unwrapped). With `zero_direction`, the
/// rotation is measured from that direction instead of the first segment (e.g. world up, for a
/// rocking unit whose two points are one above the other when it stands upright).
#[derive(Debug, Clone, PartialEq)]
pub struct PairMotion {
    pub translation: Vec<Vec3>,
    pub rotation: Vec<f64>,
}

pub fn pair_motion(
    first: &[Option<Vec3>],
    second: &[Option<Vec3>],
    plane: &Plane,
    zero_direction: Option<Vec3>,
) -> PairMotion {
    let n = linalg::norm3(&plane.normal());
    let normal = plane.normal().map(|v| v / n);
    let both: Vec<Option<(Vec3, Vec3)>> = first.iter().zip(second).map(|(a, b)| Some(((*a)?, (*b)?))).collect();
    let Some((a0, b0)) = both.iter().flatten().next().copied() else {
        return PairMotion { translation: vec![[f64::NAN; 3]; first.len()], rotation: vec![f64::NAN; first.len()] };
    };
    let mid = |a: &Vec3, b: &Vec3| [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]));
    let mid0 = mid(&a0, &b0);
    let d0 = match zero_direction {
        // Its component in the plane.
        Some(z) => {
            let along = linalg::dot3(&z, &normal);
            [0, 1, 2].map(|k| z[k] - along * normal[k])
        }
        None => [0, 1, 2].map(|k| b0[k] - a0[k]),
    };
    let mut translation = Vec::with_capacity(first.len());
    let mut rotation = Vec::with_capacity(first.len());
    let mut previous: Option<f64> = None;
    for pair in &both {
        match pair {
            Some((a, b)) => {
                let m = mid(a, b);
                translation.push([0, 1, 2].map(|k| m[k] - mid0[k]));
                let d = [0, 1, 2].map(|k| b[k] - a[k]);
                let mut angle = linalg::dot3(&normal, &linalg::cross3(&d0, &d)).atan2(linalg::dot3(&d0, &d));
                // Unwrap against the last known angle so a unit turning past ±π stays continuous.
                if let Some(p) = previous {
                    angle += (2.0 * std::f64::consts::PI) * ((p - angle) / (2.0 * std::f64::consts::PI)).round();
                }
                previous = Some(angle);
                rotation.push(angle);
            }
            None => {
                translation.push([f64::NAN; 3]);
                rotation.push(f64::NAN);
            }
        }
    }
    PairMotion { translation, rotation }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::camera::Intrinsics;

    fn camera() -> Camera {
        let k = Intrinsics { fx: 1400.0, fy: 1400.0, skew: 0.0, cx: 960.0, cy: 540.0 };
        Camera::look_at(k, [300.0, -4000.0, 2000.0], [0.0, 0.0, 500.0], -0.05, 0.0)
    }

    #[test]
    fn backprojection_inverts_projection_on_the_plane() {
        let cam = camera();
        let floor = Plane { a: 0.0, b: 0.0, c: 1.0, d: -250.0 };
        for x in [[0.0, 0.0, 250.0], [-800.0, 600.0, 250.0], [900.0, -300.0, 250.0]] {
            let pixel = cam.project(&x).unwrap();
            let back = backproject(&cam, pixel, &floor, 2.0).unwrap();
            assert!((0..3).all(|k| (back[k] - x[k]).abs() < 1e-6), "{back:?} vs {x:?}");
        }
    }

    #[test]
    fn grazing_and_behind_rays_are_refused() {
        let cam = camera();
        // A vertical plane containing the camera centre: every ray through it is parallel.
        let c = cam.centre();
        let plane = Plane { a: 1.0, b: 0.0, c: 0.0, d: -c[0] };
        let pixel = cam.project(&[c[0], 0.0, 500.0]).unwrap();
        assert!(matches!(backproject(&cam, pixel, &plane, 2.0), Err(ProjectError::GrazingRay { .. })));
        // A plane behind the camera.
        let behind = Plane { a: 0.0, b: 1.0, c: 0.0, d: 6000.0 };
        let pixel = cam.project(&[0.0, 0.0, 500.0]).unwrap();
        assert_eq!(backproject(&cam, pixel, &behind, 2.0), Err(ProjectError::BehindCamera));
    }

    #[test]
    fn pair_motion_recovers_rotation_and_translation() {
        let plane = Plane { a: 0.0, b: 1.0, c: 0.0, d: 0.0 };
        // Rotation about +Y by θ moves +Z toward +X: (x, z) → (x cos θ + z sin θ, −x sin θ + z cos θ).
        let rotate = |p: Vec3, t: f64| [p[0] * t.cos() + p[2] * t.sin() + 5.0, 0.0, -p[0] * t.sin() + p[2] * t.cos()];
        let thetas = [0.0, 0.1, -0.2, 3.0, -3.0];
        let first: Vec<Option<Vec3>> = thetas.iter().map(|&t| Some(rotate([0.0, 0.0, 100.0], t))).collect();
        let mut second: Vec<Option<Vec3>> = thetas.iter().map(|&t| Some(rotate([0.0, 0.0, 800.0], t))).collect();
        second[2] = None;
        let motion = pair_motion(&first, &second, &plane, None);
        assert!(motion.rotation[2].is_nan());
        let upright = pair_motion(&first[1..2], &second[1..2], &plane, Some([0.0, 0.0, 1.0]));
        assert!((upright.rotation[0] - 0.1).abs() < 1e-12, "{:?}", upright.rotation);
        for (k, &t) in thetas.iter().enumerate().filter(|(k, _)| *k != 2) {
            let expected = if t == -3.0 { 2.0 * std::f64::consts::PI - 3.0 } else { t };
            assert!((motion.rotation[k] - expected).abs() < 1e-12, "{k}: {} vs {expected}", motion.rotation[k]);
        }
    }
}
