//! The block rocking on a base that moves as prescribed (the floor, or an isolated base the
//! block does not load back): rest, rocking on either corner, leaning on an obstacle, overturned;
//! with tension anchors at the base corners and a change of mass at a given time (the module
//! docs of `rocking` give the equations).

use super::{
    chatter, initial_side, sensor_acceleration, Block, EventKind, Excitation, MassChange, Options, Response,
    MAX_TRANSITIONS_PER_SAMPLE,
};
use crate::physics::error::PhysicsError;
use crate::physics::hybrid::{self, rebounds, Course, Equations, Hybrid, Now, Segment};
use crate::physics::ode::{Stats, Stepper};

/// The anchorage in the quantities the equations use.
#[derive(Clone, Copy, Debug)]
struct AnchorLaw {
    /// F/W.
    strength_ratio: f64,
    /// Heel uplift at which an anchor loaded from slack yields.
    yield_m: f64,
    /// Total elongation at fracture.
    fracture_m: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum AnchorState {
    /// Elastic in tension, slack below this permanent elongation.
    Elastic {
        plastic_m: f64,
    },
    /// Yielding at the full strength while the heel keeps rising.
    Plastic,
    Fractured,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Regime {
    Rest,
    Rocking {
        side: i8,
    },
    /// Held against the obstacle.
    Leaning {
        side: i8,
    },
    Overturned,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Transition {
    /// The floor uplifts the block at rest onto this side.
    Uplift(i8),
    /// The equations pull the leaning block away from the obstacle.
    Release,
    /// The scheduled change of mass.
    MassChange,
    /// θ back to 0: rebound onto the other corner, or rest.
    Impact,
    Overturn,
    /// The heel anchor yields, unloads while yielding, fractures.
    AnchorYield,
    AnchorUnload,
    AnchorFracture,
    /// The rotation reaches the obstacle: rebound, or lean on it.
    Wall,
}

/// What the event functions of [`RockingOnSide::events`] stand for, in their order.
const ROCKING_EVENTS: [Transition; 6] = [
    Transition::Impact,
    Transition::Overturn,
    Transition::AnchorYield,
    Transition::AnchorUnload,
    Transition::AnchorFracture,
    Transition::Wall,
];

/// Heel uplift = elongation of the heel anchor, rocking on side `side` at θ.
fn heel_uplift(block: &Block, side: f64, theta: f64) -> f64 {
    2.0 * block.half_base_m * (side * theta).max(0.0).sin()
}

/// The rocking equations on one side, over one floor segment, with the heel anchor's state.
struct RockingOnSide {
    block: Block,
    side: f64,
    seg: Segment<2>,
    anchor: Option<(AnchorLaw, AnchorState)>,
    /// The obstacle's angle when it stands on this side.
    wall_rad: Option<f64>,
}

impl RockingOnSide {
    fn theta_ddot(&self, t: f64, y: &[f64; 2]) -> f64 {
        let b = &self.block;
        let [ax, av] = self.seg.at(t);
        let (sin, cos) = (self.side * b.alpha_rad - y[0]).sin_cos();
        let mut acc = -(b.r_m / b.i0_per_kg) * ((b.g_mps2 + av) * sin + ax * cos);
        if let Some((law, state)) = self.anchor {
            let force_ratio = match state {
                AnchorState::Elastic { plastic_m } => {
                    law.strength_ratio * ((heel_uplift(b, self.side, y[0]) - plastic_m) / law.yield_m).clamp(0.0, 1.0)
                }
                AnchorState::Plastic => law.strength_ratio,
                AnchorState::Fractured => 0.0,
            };
            // The anchor pulls the heel down, a lever 2b·cos θ from the pivot.
            acc -= self.side * force_ratio * b.g_mps2 * 2.0 * b.half_base_m * y[0].cos() / b.i0_per_kg;
        }
        acc
    }
}

impl Equations<2, 6> for RockingOnSide {
    type Transition = Transition;

    fn rhs(&self, t: f64, y: &[f64; 2]) -> [f64; 2] {
        [y[1], self.theta_ddot(t, y)]
    }

    /// Positive while nothing happens: θ back to 0, overturn, the heel anchor yields, the
    /// yielding anchor unloads, it fractures, the obstacle ([`ROCKING_EVENTS`]).
    fn events(&self, _: f64, y: &[f64; 2]) -> [f64; 6] {
        let s = self.side;
        let mut g = [s * y[0], self.block.lie_angle_rad - s * y[0], 1.0, 1.0, 1.0, 1.0];
        if let Some((law, state)) = self.anchor {
            let uplift = heel_uplift(&self.block, s, y[0]);
            match state {
                AnchorState::Elastic { plastic_m } => g[2] = law.yield_m - (uplift - plastic_m),
                AnchorState::Plastic => {
                    g[3] = s * y[1];
                    g[4] = law.fracture_m - uplift;
                }
                AnchorState::Fractured => {}
            }
        }
        if let Some(angle) = self.wall_rad {
            g[5] = angle - s * y[0];
        }
        g
    }

    fn transition(&self, index: usize) -> Transition {
        ROCKING_EVENTS[index]
    }
}

/// The first time in [t, t_end] at which the floor uplifts a block at rest, and the side.
fn uplift_time(block: &Block, seg: &Segment<2>, t: f64, t_end: f64) -> Option<(f64, i8)> {
    let tan = block.alpha_rad.tan();
    // φ_s > 0 uplifts toward side s; linear in time inside the segment.
    let phi = |time: f64, s: f64| {
        let [ax, av] = seg.at(time);
        -s * ax - (block.g_mps2 + av) * tan
    };
    [1i8, -1]
        .into_iter()
        .filter_map(|side| first_positive(|time| phi(time, f64::from(side)), t, t_end).map(|tu| (tu, side)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// The first time in [t, t_end] at which a function linear in time turns positive.
fn first_positive(f: impl Fn(f64) -> f64, t: f64, t_end: f64) -> Option<f64> {
    let (f0, f1) = (f(t), f(t_end));
    if f0 > 0.0 {
        Some(t)
    } else if f1 > 0.0 {
        Some((t + f0 / (f0 - f1) * (t_end - t)).clamp(t, t_end))
    } else {
        None
    }
}

/// Simulates the block on a base accelerating by `base_ax` (the floor's vertical from
/// `excitation`); the options are checked but for the anchorage.
pub(super) fn simulate<S: Stepper<2>>(
    block: &Block,
    excitation: &Excitation<'_>,
    base_ax: &[f64],
    options: &Options,
    stepper: S,
) -> Result<Response, PhysicsError> {
    let anchor = match options.anchorage {
        Some(a) => {
            if !(a.strength_ratio > 0.0 && a.ductility >= 1.0 && a.yield_rotation_rad > 0.0) {
                return Err(PhysicsError::Parameter(format!(
                    "the anchorage needs F/W > 0, ductility ≥ 1 and a positive yield rotation, got {a:?}"
                )));
            }
            let yield_m = 2.0 * block.half_base_m * a.yield_rotation_rad.sin();
            Some(AnchorLaw { strength_ratio: a.strength_ratio, yield_m, fracture_m: a.ductility * yield_m })
        }
        None => None,
    };
    let n = base_ax.len();
    let mut response = Response::with_capacity(n, false);
    response.base_ax_mps2 = base_ax.to_vec();
    let y = [options.initial_theta_rad, options.initial_theta_dot_radps];
    let mut model = Toppling {
        excitation,
        base_ax,
        options,
        anchor,
        block: *block,
        pending_change: options.mass_change,
        regime: initial_side(y[0], y[1]).map_or(Regime::Rest, |side| Regime::Rocking { side }),
        // Anchor at the −x corner (heel when pivoting on +x) and at the +x corner.
        anchors: [AnchorState::Elastic { plastic_m: 0.0 }; 2],
        response,
    };
    let stats = hybrid::drive(&mut model, excitation.clock(), MAX_TRANSITIONS_PER_SAMPLE, y, stepper)?;
    model.response.stats = stats;
    Ok(model.response)
}

/// The model's state between transitions, and what it records.
struct Toppling<'a> {
    excitation: &'a Excitation<'a>,
    base_ax: &'a [f64],
    options: &'a Options,
    anchor: Option<AnchorLaw>,
    /// The block as it is now (after a mass change, the block that remains).
    block: Block,
    pending_change: Option<MassChange>,
    regime: Regime,
    anchors: [AnchorState; 2],
    response: Response,
}

impl Toppling<'_> {
    fn segment(&self, k: usize) -> Segment<2> {
        self.excitation.clock().segment(k, |j| [self.base_ax[j], self.excitation.vertical(j)])
    }

    fn on_side(&self, side: i8, seg: Segment<2>) -> RockingOnSide {
        RockingOnSide {
            block: self.block,
            side: f64::from(side),
            seg,
            anchor: self.anchor.map(|law| (law, self.anchors[heel(side)])),
            wall_rad: self.options.obstacle.filter(|o| o.side == side).map(|o| o.angle_rad),
        }
    }

    /// The side the block rocks or leans on (0 at rest or overturned).
    fn side(&self) -> i8 {
        match self.regime {
            Regime::Rocking { side } | Regime::Leaning { side } => side,
            Regime::Rest | Regime::Overturned => 0,
        }
    }

    /// θ back to 0 at speed `before`: onto the other corner, or at rest.
    fn impact(&mut self, t: f64, before: f64, immediate: bool) -> [f64; 2] {
        let side = self.side();
        let after = self.options.restitution.unwrap_or(self.block.restitution_eq24) * before;
        if rebounds(after, immediate, self.block.rest_speed_squared(self.options.rest_amplitude_rad)) {
            self.regime = Regime::Rocking { side: -side };
            self.response.log(t, EventKind::Impact, -side, before, after);
            [0.0, after]
        } else {
            // The rebound cannot lift the block: it sits down.
            self.regime = Regime::Rest;
            self.response.log(t, EventKind::Rest, 0, before, 0.0);
            [0.0, 0.0]
        }
    }

    /// The rotation reaches the obstacle at speed `before`: it rebounds or leans there.
    fn wall(&mut self, t: f64, before: f64, immediate: bool) -> [f64; 2] {
        let side = self.side();
        let wall = self.options.obstacle.expect("only obstacles stop the rotation");
        let after = -wall.restitution * before;
        let mut y = [f64::from(side) * wall.angle_rad, after];
        if rebounds(after, immediate, self.block.rest_speed_squared(self.options.rest_amplitude_rad)) {
            self.response.log(t, EventKind::WallImpact, side, before, after);
        } else {
            self.regime = Regime::Leaning { side };
            y[1] = 0.0;
            self.response.log(t, EventKind::WallLean, side, before, 0.0);
        }
        y
    }
}

/// The anchor at the heel when pivoting on `side`: the −x corner's (0) on +x, the +x corner's (1) on −x.
fn heel(side: i8) -> usize {
    usize::from(side < 0)
}

impl Hybrid<2, 6> for Toppling<'_> {
    type Transition = Transition;
    type Equations = RockingOnSide;
    type Error = PhysicsError;

    /// A mass change splits the interval: the phase ends there and the block changes.
    fn limit(&self, t: f64, t_end: f64) -> f64 {
        match self.pending_change {
            Some(change) if change.time_s < t_end => change.time_s.max(t),
            _ => t_end,
        }
    }

    fn course(&mut self, now: Now, y: &[f64; 2]) -> Result<Course<Transition, RockingOnSide>, PhysicsError> {
        let Now { k, t, limit } = now;
        if t >= limit {
            return Ok(Course::Switch { at: t, transition: Transition::MassChange });
        }
        let seg = self.segment(k);
        Ok(match self.regime {
            Regime::Overturned => Course::Hold,
            Regime::Rest => match uplift_time(&self.block, &seg, t, limit) {
                Some((at, side)) => Course::Switch { at, transition: Transition::Uplift(side) },
                None => Course::Hold,
            },
            Regime::Leaning { side } => {
                // Held at the obstacle until the equations pull the block away from it:
                // θ̈ at fixed θ is linear in the floor, so the release is a linear root.
                let model = self.on_side(side, seg);
                let away = |time: f64| -f64::from(side) * model.theta_ddot(time, y);
                match first_positive(away, t, limit) {
                    Some(at) => Course::Switch { at, transition: Transition::Release },
                    None => Course::Hold,
                }
            }
            Regime::Rocking { side } => Course::Integrate(self.on_side(side, seg)),
        })
    }

    fn apply(&mut self, _: usize, transition: Transition, t: f64, y: [f64; 2], immediate: bool) -> [f64; 2] {
        let side = self.side();
        match transition {
            Transition::MassChange => {
                let change = self.pending_change.take().expect("the limit came from a pending change");
                self.block = change.after;
                self.response.log(t, EventKind::MassChange, 0, y[1], y[1]);
                y
            }
            Transition::Uplift(side) => {
                self.regime = Regime::Rocking { side };
                self.response.log(t, EventKind::Uplift, side, 0.0, 0.0);
                [0.0, 0.0]
            }
            Transition::Release => {
                self.regime = Regime::Rocking { side };
                self.response.log(t, EventKind::WallRelease, side, 0.0, 0.0);
                y
            }
            Transition::Impact => self.impact(t, y[1], immediate),
            Transition::Overturn => {
                self.regime = Regime::Overturned;
                self.response.overturn = Some((t, side));
                self.response.log(t, EventKind::Overturn, side, y[1], 0.0);
                [f64::from(side) * self.block.lie_angle_rad, 0.0]
            }
            Transition::AnchorYield => {
                self.anchors[heel(side)] = AnchorState::Plastic;
                self.response.log(t, EventKind::AnchorYield, side, y[1], y[1]);
                y
            }
            Transition::AnchorUnload => {
                let law = self.anchor.expect("only anchored blocks unload anchors");
                let uplift = heel_uplift(&self.block, f64::from(side), y[0]);
                self.anchors[heel(side)] = AnchorState::Elastic { plastic_m: uplift - law.yield_m };
                y
            }
            Transition::AnchorFracture => {
                self.anchors[heel(side)] = AnchorState::Fractured;
                self.response.log(t, EventKind::AnchorFracture, side, y[1], y[1]);
                y
            }
            Transition::Wall => self.wall(t, y[1], immediate),
        }
    }

    fn chatter(&self, t: f64, _: &Stats) -> PhysicsError {
        chatter("impact", t, self.options.rest_amplitude_rad)
    }

    fn record(&mut self, k: usize, y: &[f64; 2]) {
        let (ax, av) = (self.base_ax[k], self.excitation.vertical(k));
        let (theta_ddot, sensor) = match self.regime {
            Regime::Rest | Regime::Leaning { .. } | Regime::Overturned => (0.0, (ax, av)),
            Regime::Rocking { side } => {
                let acc = self.on_side(side, self.segment(k)).theta_ddot(self.excitation.clock().time(k), y);
                let point = self.options.sensor_point(&self.block);
                (acc, sensor_acceleration(&self.block, side, [y[0], y[1], acc], point, ax, av))
            }
        };
        self.response.record_motion(*y, theta_ddot, sensor, self.regime == Regime::Overturned, av);
    }
}
