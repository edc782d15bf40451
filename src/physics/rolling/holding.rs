//! Can static friction hold the cart at rest? At rest the floor's inertial load is a generalised
//! force Q = A ü (3 components: x, y, yaw) and each friction element j (four rolling, four swivel)
//! can supply any force λⱼ gⱼ with |λⱼ| ≤ 1 (gⱼ: its direction times its static capacity). The
//! cart holds iff Q lies in the zonotope Σ [−1, 1] gⱼ, which in 3D is the intersection of the
//! slabs |hᵀQ| ≤ Σⱼ |hᵀgⱼ| over the face normals h = gⱼ × gₖ. With the floor linear in time
//! over a sample interval, each slab is left at a time found in closed form.

/// The slabs bounding the holdable set: unit normals and their half-widths.
#[derive(Clone, Debug)]
pub struct HoldingSet {
    slabs: Vec<([f64; 3], f64)>,
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn norm(a: &[f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Relative size below which a cross product counts as zero (parallel generators).
const PARALLEL: f64 = 1e-12;

impl HoldingSet {
    pub fn new(generators: &[[f64; 3]]) -> Self {
        let gens: Vec<[f64; 3]> = generators.iter().copied().filter(|g| norm(g) > 0.0).collect();
        let mut normals: Vec<[f64; 3]> = Vec::new();
        for (j, a) in gens.iter().enumerate() {
            for b in &gens[j + 1..] {
                let c = cross(a, b);
                if norm(&c) > PARALLEL * norm(a) * norm(b) {
                    normals.push(c);
                }
            }
        }
        let spans_3d = normals.iter().any(|c| norm(&cross(c, &normals[0])) > PARALLEL * norm(c) * norm(&normals[0]));
        if !spans_3d {
            // A flat (or thinner) set: its plane's normal bounds it with zero width, and the
            // normals of its edges within the plane bound it there.
            let plane = match (normals.first(), gens.first()) {
                (Some(m), _) => vec![*m],
                // All generators parallel: any two directions across them have zero width.
                (None, Some(g)) => {
                    let helper = if g[0].abs() < 0.9 * norm(g) { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
                    let p = cross(g, &helper);
                    vec![p, cross(g, &p), *g]
                }
                (None, None) => vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            };
            normals = plane.clone();
            if let [m] = plane.as_slice() {
                normals.extend(gens.iter().map(|g| cross(m, g)));
            }
        }
        let slabs = normals
            .into_iter()
            .map(|c| {
                let n = norm(&c);
                let h = [c[0] / n, c[1] / n, c[2] / n];
                (h, gens.iter().map(|g| dot(&h, g).abs()).sum())
            })
            .collect();
        HoldingSet { slabs }
    }

    pub fn holds(&self, q: &[f64; 3]) -> bool {
        self.slabs.iter().all(|(h, width)| dot(h, q).abs() <= *width)
    }

    /// The first s in [0, s_max] at which q0 + s·q1 leaves the set (0 if it is already out).
    pub fn exit_time(&self, q0: &[f64; 3], q1: &[f64; 3], s_max: f64) -> Option<f64> {
        let mut first: Option<f64> = None;
        for (h, width) in &self.slabs {
            let (c0, c1) = (dot(h, q0), dot(h, q1));
            let s = if c0.abs() > *width {
                0.0
            } else if c1 > 0.0 {
                (width - c0) / c1
            } else if c1 < 0.0 {
                (-width - c0) / c1
            } else {
                continue;
            };
            if s <= s_max && first.is_none_or(|f| s < f) {
                first = Some(s);
            }
        }
        first
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_box_holds_inside_and_exits_on_time() {
        let set = HoldingSet::new(&[[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]]);
        assert!(set.holds(&[1.9, -0.9, 2.9]));
        assert!(!set.holds(&[2.1, 0.0, 0.0]));
        // Moving along +x at 1 per unit time from x = 0.5: leaves at x = 2, s = 1.5.
        let s = set.exit_time(&[0.5, 0.0, 0.0], &[1.0, 0.0, 0.0], 10.0).unwrap();
        assert!((s - 1.5).abs() < 1e-15);
        assert_eq!(set.exit_time(&[0.5, 0.0, 0.0], &[1.0, 0.0, 0.0], 1.0), None);
    }

    #[test]
    fn redundant_generators_add_up() {
        // Two generators along x (capacities 1 and 2) and one along y: |x| ≤ 3 but a diagonal
        // load uses both at once, |x| + ... as the zonotope (a rectangle here) says.
        let set = HoldingSet::new(&[[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert!(set.holds(&[2.99, 0.99, 0.0]));
        assert!(!set.holds(&[3.01, 0.0, 0.0]));
        assert!(!set.holds(&[0.0, 0.0, 1e-9]), "nothing holds a yaw load");
        let sheared = HoldingSet::new(&[[1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.0, 1.0]]);
        assert!(sheared.holds(&[1.99, 0.0, 0.0]) && !sheared.holds(&[1.5, 0.6, 0.0]));
    }
}
