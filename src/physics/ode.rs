//! Explicit integrators with event location, shared by the rocking and rolling models.
//!
//! [`Dopri5`] is the Dormand–Prince 5(4) pair with Hairer's step-size control and 4th-order
//! dense output (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.4–II.6, code `DOPRI5`).
//! [`Rk4`] is the classical fixed-step Runge–Kutta method the study used (dt = 1e-4 s), kept as
//! the accuracy reference. Both locate events on their continuous output and stop there, so a
//! model can apply an impact or switch a regime exactly where it happens.
//!
//! Why written here rather than taken from a crate: the models have 2 to 10 states; const-generic
//! arrays keep every stage on the stack, and no maintained crate offers dense-output root finding
//! without a second linear-algebra stack (see STACK-NOTES.md). Forcing is sampled data, linear
//! between samples, so callers advance one sample interval at a time and every sample time is a
//! step end: outputs on the input time base need no interpolation, and no step straddles a kink
//! of the forcing.

/// Work counters, for benchmarks and convergence reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    pub accepted: usize,
    pub rejected: usize,
    pub rhs_evals: usize,
    pub events: usize,
}

/// How an [`Stepper::advance`] call ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Advance<const N: usize> {
    /// The end time was reached with this state.
    Reached([f64; N]),
    /// Event `index` fired first, at time `t` with state `y` (on the continuous output).
    Event { index: usize, t: f64, y: [f64; N] },
}

/// Something that integrates y' = f(t, y) from `t0` to `t1` and stops at the first event.
///
/// Event functions `g(t, y) -> [f64; M]` describe where the trajectory may go: event `i` fires
/// the first time `g[i]` reaches zero from above after having been positive. An event that is
/// zero at `t0` (a trajectory leaving a boundary, e.g. θ = 0 right after an impact) is armed as
/// soon as it turns positive; if it never does within the first step and ends negative, it fires
/// at `t0` itself, which tells the caller the trajectory cannot leave the boundary that way.
pub trait Stepper<const N: usize> {
    fn advance<F, G, const M: usize>(&mut self, f: &F, t0: f64, y0: [f64; N], t1: f64, g: &G) -> Advance<N>
    where
        F: Fn(f64, &[f64; N]) -> [f64; N],
        G: Fn(f64, &[f64; N]) -> [f64; M];

    /// Forget derivative values carried between calls (after a state reset or a model switch).
    fn reset(&mut self);

    fn stats(&self) -> Stats;
}

/// Dormand–Prince 5(4) with PI step-size control and dense output.
#[derive(Debug, Clone)]
pub struct Dopri5<const N: usize> {
    pub rtol: f64,
    pub atol: [f64; N],
    /// Largest step; the sample interval of the forcing is a natural bound.
    pub h_max: f64,
    /// Step size carried from one call to the next (0: choose one).
    h: f64,
    facold: f64,
    /// f(t, y) at the end of the last accepted step (first-same-as-last), reused when the next
    /// call starts from exactly that point.
    fsal: Option<(f64, [f64; N], [f64; N])>,
    stats: Stats,
    /// Evaluations past which a step is not tried (None: no limit): a problem so stiff that its
    /// steps shrink to the floor of the time's resolution crawls otherwise for hours inside one
    /// call, between its caller's checks. The call then returns a NaN state for it to refuse.
    max_evals: Option<usize>,
}

// Dormand–Prince coefficients (Hairer's DOPRI5).
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// Continuous output over one accepted step.
trait Dense<const N: usize> {
    fn eval(&self, t: f64) -> [f64; N];
}

/// Hairer's order-4 continuous extension of a Dormand–Prince step.
struct DopriDense<const N: usize> {
    t0: f64,
    h: f64,
    r: [[f64; N]; 5],
}

impl<const N: usize> Dense<N> for DopriDense<N> {
    fn eval(&self, t: f64) -> [f64; N] {
        let s = (t - self.t0) / self.h;
        let s1 = 1.0 - s;
        let r = &self.r;
        std::array::from_fn(|i| r[0][i] + s * (r[1][i] + s1 * (r[2][i] + s * (r[3][i] + s1 * r[4][i]))))
    }
}

/// Cubic Hermite interpolation between two states and their derivatives (for [`Rk4`]).
struct HermiteDense<const N: usize> {
    t0: f64,
    h: f64,
    y0: [f64; N],
    f0: [f64; N],
    y1: [f64; N],
    f1: [f64; N],
}

impl<const N: usize> Dense<N> for HermiteDense<N> {
    fn eval(&self, t: f64) -> [f64; N] {
        let s = (t - self.t0) / self.h;
        let (s2, s3) = (s * s, s * s * s);
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        std::array::from_fn(|i| {
            h00 * self.y0[i] + h10 * self.h * self.f0[i] + h01 * self.y1[i] + h11 * self.h * self.f1[i]
        })
    }
}

/// Event bookkeeping across the steps of one `advance` call.
struct EventWatch<const M: usize> {
    /// Last time each event function was seen positive (None: not armed yet).
    positive_at: [Option<f64>; M],
    /// The value of g there.
    positive_g: [f64; M],
}

impl<const M: usize> EventWatch<M> {
    fn new(g0: [f64; M], t0: f64) -> Self {
        let mut positive_at = [None; M];
        for (i, &g) in g0.iter().enumerate() {
            if g > 0.0 {
                positive_at[i] = Some(t0);
            }
        }
        EventWatch { positive_at, positive_g: g0 }
    }

    /// Checks one accepted step [t0, t1] on its dense output; returns the earliest event.
    ///
    /// Event functions are sampled at the step's start, quarters and end. Besides sign changes
    /// between samples, a dip between three positive samples (a trajectory grazing its boundary,
    /// e.g. a small rocking excursion inside one step) is searched for its minimum, so an impact
    /// is not missed because it fell between samples.
    // `i` indexes three arrays and a closure: an index loop is the clearest.
    #[allow(clippy::needless_range_loop)]
    fn check<const N: usize, G, D>(
        &mut self,
        g: &G,
        dense: &D,
        t0: f64,
        t1: f64,
        first_step: bool,
    ) -> Option<(usize, f64, [f64; N])>
    where
        G: Fn(f64, &[f64; N]) -> [f64; M],
        D: Dense<N>,
    {
        let h = t1 - t0;
        let times: [f64; 5] = std::array::from_fn(|j| if j == 4 { t1 } else { t0 + 0.25 * j as f64 * h });
        let values: [[f64; M]; 5] = std::array::from_fn(|j| g(times[j], &dense.eval(times[j])));
        let mut earliest: Option<(usize, f64)> = None;
        for i in 0..M {
            let g_at = |s: f64| g(s, &dense.eval(s))[i];
            // A function that starts on its boundary may turn positive and come back before the
            // first quarter: look for its positive stretch closer to the start.
            if self.positive_at[i].is_none() && first_step && values[1][i] <= 0.0 {
                if let Some((ta, ga)) =
                    (1..=24).map(|k| t0 + 0.25 * h * 0.25f64.powi(k)).map(|s| (s, g_at(s))).find(|&(_, v)| v > 0.0)
                {
                    self.positive_at[i] = Some(ta);
                    self.positive_g[i] = ga;
                }
            }
            let mut found = None;
            for j in 1..5 {
                let value = values[j][i];
                if value <= 0.0 {
                    found = match self.positive_at[i] {
                        Some(ta) => Some(locate_root(g_at, ta, self.positive_g[i], times[j], value)),
                        // Never positive since the start of the first step: the trajectory cannot
                        // leave the boundary in the direction the event function describes.
                        None if first_step && j == 4 => Some(t0),
                        None => None,
                    };
                    if found.is_some() {
                        break;
                    }
                    continue;
                }
                if j >= 2 && self.positive_at[i].is_some() && values[j - 2][i] > 0.0 && values[j - 1][i] > 0.0 {
                    if let Some((tm, gm)) = dip_minimum(
                        &g_at,
                        [times[j - 2], times[j - 1], times[j]],
                        [values[j - 2][i], values[j - 1][i], value],
                    ) {
                        if gm <= 0.0 {
                            found = Some(locate_root(g_at, times[j - 2], values[j - 2][i], tm, gm));
                            break;
                        }
                    }
                }
                self.positive_at[i] = Some(times[j]);
                self.positive_g[i] = value;
            }
            if let Some(root) = found {
                if earliest.is_none_or(|(_, te)| root < te) {
                    earliest = Some((i, root));
                }
            }
        }
        earliest.map(|(i, t)| (i, t, dense.eval(t)))
    }
}

/// The minimum of g over [t_a, t_c] when three positive samples suggest a dip (the middle one
/// is the lowest and the parabola through them goes below half of it): golden-section search.
fn dip_minimum(g: &impl Fn(f64) -> f64, t: [f64; 3], v: [f64; 3]) -> Option<(f64, f64)> {
    if !(v[1] < v[0] && v[1] < v[2]) {
        return None;
    }
    // Parabola through equally spaced samples: vertex value v1 − (v2 − v0)²/(8(v0 − 2v1 + v2)).
    let curvature = v[0] - 2.0 * v[1] + v[2];
    let vertex = v[1] - (v[2] - v[0]).powi(2) / (8.0 * curvature);
    if vertex > 0.5 * v[1] {
        return None;
    }
    const INV_PHI: f64 = 0.618_033_988_749_894_9;
    let (mut a, mut b) = (t[0], t[2]);
    let mut c = b - INV_PHI * (b - a);
    let mut d = a + INV_PHI * (b - a);
    let (mut gc, mut gd) = (g(c), g(d));
    for _ in 0..60 {
        if gc.min(gd) <= 0.0 || b - a < 1e-13 * (1.0 + b.abs()) {
            break;
        }
        if gc < gd {
            (b, d, gd) = (d, c, gc);
            c = b - INV_PHI * (b - a);
            gc = g(c);
        } else {
            (a, c, gc) = (c, d, gd);
            d = a + INV_PHI * (b - a);
            gd = g(d);
        }
    }
    Some(if gc < gd { (c, gc) } else { (d, gd) })
}

/// Root of a continuous g on [a, b] with g(a) > 0 ≥ g(b): Illinois regula falsi, to 1e-13 s.
/// The result is the right end of the final bracket, where g ≤ 0, so the event has happened.
fn locate_root(g: impl Fn(f64) -> f64, mut a: f64, mut ga: f64, mut b: f64, mut gb: f64) -> f64 {
    const T_TOL: f64 = 1e-13;
    let mut side = 0;
    for _ in 0..200 {
        if b - a <= T_TOL * (1.0 + b.abs()) || gb == 0.0 {
            break;
        }
        let mut c = b - gb * (b - a) / (gb - ga);
        // Keep the iterate strictly inside; fall back to bisection on stagnation.
        if !(c > a && c < b) {
            c = 0.5 * (a + b);
        }
        let gc = g(c);
        if gc > 0.0 {
            a = c;
            ga = gc;
            if side == 1 {
                gb *= 0.5;
            }
            side = 1;
        } else {
            b = c;
            gb = gc;
            if side == -1 {
                ga *= 0.5;
            }
            side = -1;
        }
    }
    b
}

impl<const N: usize> Dopri5<N> {
    pub fn new(rtol: f64, atol: [f64; N], h_max: f64) -> Self {
        assert!(rtol > 0.0 && atol.iter().all(|&a| a > 0.0), "tolerances must be positive");
        Dopri5 { rtol, atol, h_max, h: 0.0, facold: 1e-4, fsal: None, stats: Stats::default(), max_evals: None }
    }

    /// The same stepper giving up past `max_evals` right-hand-side evaluations in all.
    pub fn with_max_evals(self, max_evals: Option<usize>) -> Self {
        Dopri5 { max_evals, ..self }
    }

    /// Hairer's initial step guess (HNW I, §II.4), bounded by the interval and `h_max`.
    fn initial_step<F>(&mut self, f: &F, t0: f64, y0: &[f64; N], f0: &[f64; N], span: f64) -> f64
    where
        F: Fn(f64, &[f64; N]) -> [f64; N],
    {
        let sk: [f64; N] = std::array::from_fn(|i| self.atol[i] + self.rtol * y0[i].abs());
        let norm = |v: &[f64; N]| (v.iter().zip(&sk).map(|(x, s)| (x / s).powi(2)).sum::<f64>() / N as f64).sqrt();
        let (d0, d1) = (norm(y0), norm(f0));
        let mut h = if d0 < 1e-10 || d1 < 1e-10 { 1e-6 } else { 0.01 * d0 / d1 };
        h = h.min(self.h_max).min(span);
        let y1: [f64; N] = std::array::from_fn(|i| y0[i] + h * f0[i]);
        let f1 = f(t0 + h, &y1);
        self.stats.rhs_evals += 1;
        let diff: [f64; N] = std::array::from_fn(|i| f1[i] - f0[i]);
        let d2 = norm(&diff) / h;
        let h1 = if d1.max(d2) <= 1e-15 { (h * 1e-3).max(1e-6) } else { (0.01 / d1.max(d2)).powf(0.2) };
        (100.0 * h).min(h1).min(self.h_max).min(span)
    }
}

impl<const N: usize> Stepper<N> for Dopri5<N> {
    fn advance<F, G, const M: usize>(&mut self, f: &F, t0: f64, y0: [f64; N], t1: f64, g: &G) -> Advance<N>
    where
        F: Fn(f64, &[f64; N]) -> [f64; N],
        G: Fn(f64, &[f64; N]) -> [f64; M],
    {
        let mut t = t0;
        let mut y = y0;
        if t1 <= t0 {
            return Advance::Reached(y0);
        }
        let mut k1 = match self.fsal {
            Some((ts, ys, fs)) if ts == t0 && ys == y0 => fs,
            _ => {
                self.stats.rhs_evals += 1;
                f(t0, &y0)
            }
        };
        if self.h <= 0.0 {
            self.h = self.initial_step(f, t0, &y0, &k1, t1 - t0);
        }
        let mut watch = EventWatch::new(g(t0, &y0), t0);
        let mut first_step = true;
        let mut h = self.h.min(self.h_max);
        loop {
            if self.max_evals.is_some_and(|m| self.stats.rhs_evals > m) {
                self.fsal = None;
                return Advance::Reached([f64::NAN; N]);
            }
            let remaining = t1 - t;
            // Land exactly on t1 rather than leave a sliver of an interval.
            let proposed = h;
            let last = h >= remaining * (1.0 - 1e-12);
            if last {
                h = remaining;
            }
            let stage = |k: &[&[f64; N]], a: &[f64]| -> [f64; N] {
                std::array::from_fn(|i| y[i] + h * k.iter().zip(a).map(|(kj, aj)| aj * kj[i]).sum::<f64>())
            };
            let k2 = f(t + C2 * h, &stage(&[&k1], &[A21]));
            let k3 = f(t + C3 * h, &stage(&[&k1, &k2], &[A31, A32]));
            let k4 = f(t + C4 * h, &stage(&[&k1, &k2, &k3], &[A41, A42, A43]));
            let k5 = f(t + C5 * h, &stage(&[&k1, &k2, &k3, &k4], &[A51, A52, A53, A54]));
            let k6 = f(t + h, &stage(&[&k1, &k2, &k3, &k4, &k5], &[A61, A62, A63, A64, A65]));
            let y_new: [f64; N] = std::array::from_fn(|i| {
                y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i])
            });
            let t_new = if last { t1 } else { t + h };
            let k7 = f(t_new, &y_new);
            self.stats.rhs_evals += 6;
            let mut err = 0.0;
            for i in 0..N {
                let e = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
                let sk = self.atol[i] + self.rtol * y[i].abs().max(y_new[i].abs());
                err += (e / sk).powi(2);
            }
            let err = (err / N as f64).sqrt();
            if !err.is_finite() && h <= 1e-14 * t.abs().max(1.0) {
                // Not a number even at the smallest step: the model failed here. Say so with a
                // NaN state for the caller to refuse, rather than step on with a NaN time.
                self.fsal = None;
                return Advance::Reached([f64::NAN; N]);
            }
            // Hairer's PI controller: safety 0.9, β = 0.04, step ratio within [0.2, 10].
            let fac11 = err.powf(0.17);
            if err <= 1.0 || h <= 1e-14 * t.abs().max(1.0) {
                let fac = (fac11 / self.facold.powf(0.04) / 0.9).clamp(0.1, 5.0);
                let h_next = (h / fac).min(self.h_max);
                self.facold = err.max(1e-4);
                self.stats.accepted += 1;
                let ydiff: [f64; N] = std::array::from_fn(|i| y_new[i] - y[i]);
                let bspl: [f64; N] = std::array::from_fn(|i| h * k1[i] - ydiff[i]);
                let dense = DopriDense {
                    t0: t,
                    h: t_new - t,
                    r: [
                        y,
                        ydiff,
                        bspl,
                        std::array::from_fn(|i| ydiff[i] - h * k7[i] - bspl[i]),
                        std::array::from_fn(|i| {
                            h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i])
                        }),
                    ],
                };
                if let Some((index, te, ye)) = watch.check(g, &dense, t, t_new, first_step) {
                    self.stats.events += 1;
                    self.fsal = None;
                    // The step that found the event was sound: keep its size for the restart.
                    self.h = h;
                    return Advance::Event { index, t: te, y: ye };
                }
                first_step = false;
                t = t_new;
                y = y_new;
                k1 = k7;
                if last {
                    self.fsal = Some((t, y, k1));
                    // A landing step shortened to reach t1 says little about the scale of the
                    // solution: carry the larger of its successor and the step it replaced.
                    self.h = h_next.max(proposed).min(self.h_max);
                    return Advance::Reached(y);
                }
                h = h_next;
                self.h = h;
            } else {
                self.stats.rejected += 1;
                h /= (fac11 / 0.9).min(5.0);
            }
        }
    }

    fn reset(&mut self) {
        self.fsal = None;
    }

    fn stats(&self) -> Stats {
        self.stats
    }
}

/// Classical fixed-step Runge–Kutta (the study's integrator), with events located on a cubic
/// Hermite interpolant between steps.
#[derive(Debug, Clone)]
pub struct Rk4 {
    pub dt: f64,
    stats: Stats,
}

impl Rk4 {
    pub fn new(dt: f64) -> Self {
        assert!(dt > 0.0, "step must be positive");
        Rk4 { dt, stats: Stats::default() }
    }
}

impl<const N: usize> Stepper<N> for Rk4 {
    fn advance<F, G, const M: usize>(&mut self, f: &F, t0: f64, y0: [f64; N], t1: f64, g: &G) -> Advance<N>
    where
        F: Fn(f64, &[f64; N]) -> [f64; N],
        G: Fn(f64, &[f64; N]) -> [f64; M],
    {
        if t1 <= t0 {
            return Advance::Reached(y0);
        }
        // Whole steps of at most dt that land exactly on t1.
        let steps = ((t1 - t0) / self.dt * (1.0 - 1e-12)).ceil().max(1.0) as usize;
        let h = (t1 - t0) / steps as f64;
        let mut watch = EventWatch::new(g(t0, &y0), t0);
        let (mut t, mut y) = (t0, y0);
        let mut k1 = f(t, &y);
        self.stats.rhs_evals += 1;
        for step in 0..steps {
            let add = |k: &[f64; N], c: f64| -> [f64; N] { std::array::from_fn(|i| y[i] + c * k[i]) };
            let k2 = f(t + 0.5 * h, &add(&k1, 0.5 * h));
            let k3 = f(t + 0.5 * h, &add(&k2, 0.5 * h));
            let k4 = f(t + h, &add(&k3, h));
            let y_new: [f64; N] = std::array::from_fn(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
            let t_new = if step + 1 == steps { t1 } else { t0 + (step + 1) as f64 * h };
            let f_new = f(t_new, &y_new);
            self.stats.rhs_evals += 4;
            self.stats.accepted += 1;
            let dense = HermiteDense { t0: t, h: t_new - t, y0: y, f0: k1, y1: y_new, f1: f_new };
            if let Some((index, te, ye)) = watch.check(g, &dense, t, t_new, step == 0) {
                self.stats.events += 1;
                return Advance::Event { index, t: te, y: ye };
            }
            t = t_new;
            y = y_new;
            k1 = f_new;
        }
        Advance::Reached(y)
    }

    fn reset(&mut self) {}

    fn stats(&self) -> Stats {
        self.stats
    }
}

/// Either stepper, chosen at run time (a model's `Method`): one driver instance serves both.
#[derive(Debug, Clone)]
pub enum Either<const N: usize> {
    Dopri5(Dopri5<N>),
    Rk4(Rk4),
}

impl<const N: usize> Stepper<N> for Either<N> {
    fn advance<F, G, const M: usize>(&mut self, f: &F, t0: f64, y0: [f64; N], t1: f64, g: &G) -> Advance<N>
    where
        F: Fn(f64, &[f64; N]) -> [f64; N],
        G: Fn(f64, &[f64; N]) -> [f64; M],
    {
        match self {
            Either::Dopri5(s) => s.advance(f, t0, y0, t1, g),
            Either::Rk4(s) => s.advance(f, t0, y0, t1, g),
        }
    }

    fn reset(&mut self) {
        match self {
            Either::Dopri5(s) => s.reset(),
            Either::Rk4(s) => Stepper::<N>::reset(s),
        }
    }

    fn stats(&self) -> Stats {
        match self {
            Either::Dopri5(s) => s.stats(),
            Either::Rk4(s) => Stepper::<N>::stats(s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_events(_: f64, _: &[f64; 2]) -> [f64; 0] {
        []
    }

    /// Harmonic oscillator y'' = -y: the exact solution is cos t.
    fn oscillator(_: f64, y: &[f64; 2]) -> [f64; 2] {
        [y[1], -y[0]]
    }

    #[test]
    fn dopri5_reaches_the_exact_solution_within_tolerance() {
        let mut solver = Dopri5::new(1e-10, [1e-12; 2], 1.0);
        let Advance::Reached(y) = solver.advance(&oscillator, 0.0, [1.0, 0.0], 10.0, &no_events) else {
            panic!("no event expected")
        };
        assert!((y[0] - 10f64.cos()).abs() < 1e-8, "{} vs {}", y[0], 10f64.cos());
        assert!((y[1] + 10f64.sin()).abs() < 1e-8);
        // Order 5: tightening the tolerance by 1e5 costs about 1e5^(1/5) = 10 times the steps
        // (a lower order would cost 18× at order 4, 32× at order 3).
        let mut loose = Dopri5::new(1e-5, [1e-7; 2], 1.0);
        let Advance::Reached(_) = loose.advance(&oscillator, 0.0, [1.0, 0.0], 10.0, &no_events) else { panic!() };
        let ratio = solver.stats().accepted as f64 / loose.stats().accepted as f64;
        assert!((6.0..15.0).contains(&ratio), "steps {:?} vs {:?}: ratio {ratio}", solver.stats(), loose.stats());
    }

    #[test]
    fn a_stepper_past_its_evaluations_gives_up_inside_the_call() {
        // A stiff decay (λ = −1e9) at an explicit method's stability limit: steps of ~3e-9 s, so
        // 1 s would take some 2e9 evaluations. Limited to 10 000, one call stops after at most
        // one more step (7 evaluations) and says so with a NaN state; unlimited, it would crawl.
        let stiff = |_: f64, y: &[f64; 1]| [-1e9 * (y[0] - 1.0)];
        let none = |_: f64, _: &[f64; 1]| -> [f64; 0] { [] };
        let mut solver = Dopri5::new(1e-6, [1e-9], 1.0).with_max_evals(Some(10_000));
        let Advance::Reached(y) = solver.advance(&stiff, 0.0, [0.0], 1.0, &none) else { panic!("no event expected") };
        assert!(y[0].is_nan(), "gave {y:?}");
        let spent = solver.stats().rhs_evals;
        assert!((10_000..=10_007).contains(&spent), "{spent} evaluations");
        // Within its limit the same stepper is the plain one.
        let mut limited = Dopri5::new(1e-10, [1e-12; 2], 1.0).with_max_evals(Some(1_000_000));
        let Advance::Reached(y) = limited.advance(&oscillator, 0.0, [1.0, 0.0], 10.0, &no_events) else { panic!() };
        assert!((y[0] - 10f64.cos()).abs() < 1e-8);
    }

    #[test]
    fn events_are_located_on_the_dense_output_between_steps() {
        // Steps of up to 0.5 s at a loose tolerance: the zero of cos falls inside a step and is
        // found on the order-4 continuous extension, to the tolerance's accuracy.
        let mut solver = Dopri5::new(1e-6, [1e-6; 2], 0.5);
        let t_event = std::f64::consts::FRAC_PI_2; // cos t = 0
        let g = |_: f64, y: &[f64; 2]| [y[0]];
        match solver.advance(&oscillator, 0.0, [1.0, 0.0], 3.0, &g) {
            Advance::Event { index: 0, t, y } => {
                assert!((t - t_event).abs() < 1e-6, "event at {t}, expected {t_event}");
                assert!(y[0].abs() < 1e-12, "the state at the event sits on the boundary: {}", y[0]);
            }
            other => panic!("expected the zero crossing, got {other:?}"),
        }
    }

    #[test]
    fn rk4_converges_at_fourth_order() {
        let error = |dt: f64| {
            let mut rk = Rk4::new(dt);
            let Advance::Reached(y) = rk.advance(&oscillator, 0.0, [1.0, 0.0], 5.0, &no_events) else { panic!() };
            (y[0] - 5f64.cos()).abs()
        };
        let ratio = error(0.02) / error(0.01);
        // 2^4 = 16 for a fourth-order method.
        assert!((ratio - 16.0).abs() < 1.0, "error ratio {ratio}");
    }

    #[test]
    fn an_event_leaving_a_boundary_arms_once_positive() {
        // Starts on g = y0 = 0 moving up (y' = 1 at t=0), so the event must not fire at t = 0
        // but at the next zero, t = π.
        let g = |_: f64, y: &[f64; 2]| [y[0]];
        let mut solver = Dopri5::new(1e-10, [1e-12; 2], 0.1);
        match solver.advance(&oscillator, 0.0, [0.0, 1.0], 10.0, &g) {
            Advance::Event { t, .. } => assert!((t - std::f64::consts::PI).abs() < 1e-8, "{t}"),
            other => panic!("{other:?}"),
        }
        // Moving down from the boundary: the event fires at the start.
        match solver.advance(&oscillator, 0.0, [0.0, -1.0], 10.0, &g) {
            Advance::Event { t, .. } => assert_eq!(t, 0.0),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn rk4_locates_events_on_its_hermite_interpolant() {
        let g = |_: f64, y: &[f64; 2]| [y[0]];
        let mut rk = Rk4::new(1e-3);
        match rk.advance(&oscillator, 0.0, [1.0, 0.0], 3.0, &g) {
            Advance::Event { t, .. } => assert!((t - std::f64::consts::FRAC_PI_2).abs() < 1e-9, "{t}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn consecutive_calls_reuse_the_last_derivative() {
        let mut solver = Dopri5::new(1e-8, [1e-10; 2], 0.05);
        let mut y = [1.0, 0.0];
        for k in 0..100 {
            let (t0, t1) = (k as f64 * 0.05, (k + 1) as f64 * 0.05);
            let Advance::Reached(next) = solver.advance(&oscillator, t0, y, t1, &no_events) else { panic!() };
            y = next;
        }
        let stats = solver.stats();
        // Six new evaluations per accepted step (plus rejected ones and the very first point).
        assert_eq!(stats.rhs_evals, 6 * (stats.accepted + stats.rejected) + 2, "{stats:?}");
        assert!((y[0] - 5f64.cos()).abs() < 1e-7);
    }
}
