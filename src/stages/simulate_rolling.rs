//! `simulate_rolling`: equipment on four swivel casters under two horizontal floor components
//! (the study's 4WMC model made well posed; `physics::rolling`). Parameters come in layers: a
//! Table 4 `preset`, then an `equipment` file of the same keys, then the stage's own values.

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde_json::{json, Map, Value};

use super::error::StageError;
use super::{f64_columns, Declared, Stage, StageContext};
use crate::physics::rolling::{
    self, simulate, Cart, EventKind, Excitation, Friction, FrictionLaw, LateralSlip, Method, Options, Response,
    Stribeck,
};
use crate::pipeline::params::{self, ParamError, ParamKind, Params};
use crate::summary;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The model keys, typed: what a preset, an equipment file or the stage's own values give, None
    /// where one does not.
    #[derive(Default, Clone)]
    pub struct RollingModel {
        /// platform length 2a (body x; caster pivots at its corners)
        pub length_m: Option<f64> [default = null, unit = "m", range = (0.0, 100.0)],
        /// platform width 2b (body y)
        pub width_m: Option<f64> [default = null, unit = "m", range = (0.0, 100.0)],
        /// platform mass m_p (centre of mass at the platform's centre)
        pub platform_mass_kg: Option<f64> [default = null, unit = "kg", range = (0.0, 1e6)],
        /// caster wheel diameter
        pub wheel_diameter_m: Option<f64> [default = null, unit = "m", range = (0.0, 10.0)],
        /// caster wheel width
        pub wheel_width_m: Option<f64> [default = null, unit = "m", range = (0.0, 10.0)],
        /// mass of one caster wheel
        pub wheel_mass_kg: Option<f64> [default = null, unit = "kg", range = (0.0, 1e4)],
        /// initial yaw θ of the platform's length axis from floor X (null: 0)
        pub yaw0_deg: Option<f64> [default = null, unit = "deg", range = (-360.0, 360.0)],
        /// initial steering angles δ from the length axis, wheels 1 (+a,+b) front left, 2 (−a,+b) rear left, 3
        /// (−a,−b) rear right, 4 (+a,−b) front right; δ = 0 trails for motion toward +x (null: 0)
        pub steer0_deg: Option<[f64; 4]> [default = null, unit = "deg", range = (-360.0, 360.0)],
        /// static rolling friction coefficient μ_sφ (Eq. 13)
        pub mu_s_roll: Option<f64> [default = null, range = (0.0, 10.0)],
        /// static swivel friction coefficient μ_sδ (Eq. 14)
        pub mu_s_swivel: Option<f64> [default = null, range = (0.0, 10.0)],
        /// kinetic rolling friction coefficient μ_kφ
        pub mu_k_roll: Option<f64> [default = null, range = (0.0, 10.0)],
        /// kinetic swivel friction coefficient μ_kδ
        pub mu_k_swivel: Option<f64> [default = null, range = (0.0, 10.0)],
        /// Stribeck transition sharpness β (on sliding speeds)
        pub beta_spm: Option<f64> [default = null, unit = "s/m", range = (0.0, 1e6)],
        /// viscous friction term γ_n (for p = 1)
        pub gamma_n: Option<f64> [default = null, unit = "s/m", range = (0.0, 1e6)],
        /// velocity exponent of the viscous term (null: 1)
        pub p: Option<f64> [default = null, range = (0.0, 10.0)],
        /// caster trail d (the study gives none; null: 0.3 × wheel diameter, at least 5 mm; 0 needs lateral_slip)
        pub trail_m: Option<f64> [default = null, unit = "m", range = (0.0, 10.0)],
        /// lever arm ρ of the swivel friction torque μ_δ N ρ (null: 0.02, a swivel bearing's radius; 1 reproduces the
        /// study's numbers literally)
        pub swivel_arm_m: Option<f64> [default = null, unit = "m", range = (0.0, 10.0)],
        /// ε of the rolling friction's regularised sign tanh(v/ε) (null: 1e-4)
        pub friction_eps: Option<f64> [default = null, unit = "m/s", range = (0.0, 1.0)],
        /// ε_sw of the swivel friction's regularised sign tanh(δ̇/ε_sw) (null: 1e-3, from a convergence study:
        /// docs/models/rolling.md)
        pub friction_eps_swivel: Option<f64> [default = null, unit = "rad/s", range = (0.0, 10.0)],
    }
}

impl RollingModel {
    /// Each value of `self`, else the one of `under` (the layer below).
    fn over(self, under: RollingModel) -> RollingModel {
        RollingModel {
            length_m: self.length_m.or(under.length_m),
            width_m: self.width_m.or(under.width_m),
            platform_mass_kg: self.platform_mass_kg.or(under.platform_mass_kg),
            wheel_diameter_m: self.wheel_diameter_m.or(under.wheel_diameter_m),
            wheel_width_m: self.wheel_width_m.or(under.wheel_width_m),
            wheel_mass_kg: self.wheel_mass_kg.or(under.wheel_mass_kg),
            yaw0_deg: self.yaw0_deg.or(under.yaw0_deg),
            steer0_deg: self.steer0_deg.or(under.steer0_deg),
            mu_s_roll: self.mu_s_roll.or(under.mu_s_roll),
            mu_s_swivel: self.mu_s_swivel.or(under.mu_s_swivel),
            mu_k_roll: self.mu_k_roll.or(under.mu_k_roll),
            mu_k_swivel: self.mu_k_swivel.or(under.mu_k_swivel),
            beta_spm: self.beta_spm.or(under.beta_spm),
            gamma_n: self.gamma_n.or(under.gamma_n),
            p: self.p.or(under.p),
            trail_m: self.trail_m.or(under.trail_m),
            swivel_arm_m: self.swivel_arm_m.or(under.swivel_arm_m),
            friction_eps: self.friction_eps.or(under.friction_eps),
            friction_eps_swivel: self.friction_eps_swivel.or(under.friction_eps_swivel),
        }
    }
}

crate::stage_params! {
    /// The parameters of `simulate_rolling` (`report` reads `figure` from the events' provenance).
    pub struct SimulateRollingParams {
        #[flatten]
        pub model: RollingModel,
        // A row of `rolling::PRESETS` (the table is the list, so it stays a name).
        /// Table 4 of the study: the model keys of the stretcher PS1, patient bed PB2, metal cart MC2 or ultrasound
        /// imager UI3
        pub preset: Option<String> [default = null, kind = ParamKind::Choice(rolling::PRESETS)],
        /// YAML file of model keys (length_m … friction_eps_swivel), over the preset; the stage's own values win
        pub equipment: Option<PathBuf> [default = null],
        /// name of the unit in tables and figures (null: the preset, the equipment file's stem, or `cart`)
        pub unit: Option<String> [default = null],
        /// input column of the floor acceleration along X (E-W)
        pub x_channel: String [default = "ax_mps2", unit = "m/s^2"],
        /// input column of the floor acceleration along Y (N-S)
        pub y_channel: String [default = "ay_mps2", unit = "m/s^2"],
        /// regularised: tanh(v/ε) sign everywhere (resting becomes a creep); stick_slip: the cart rests exactly while
        /// static friction holds it and breaks away exactly where it cannot
        pub friction_law: FrictionLawChoice [default = "regularised"],
        /// let the wheels slip sideways against a regularised Coulomb force (each caster heading becomes free; allows
        /// trail_m = 0)
        pub lateral_slip: bool [default = false],
        /// sideways friction coefficient of the wheels (lateral_slip)
        pub mu_lateral: f64 [default = 0.5, range = (0.0, 10.0)],
        /// ε of the sideways friction tanh(v/ε) (lateral_slip; smaller is stiffer and slower)
        pub lateral_eps: f64 [default = 0.001, unit = "m/s", range = (0.0, 1.0)],
        /// adaptive: Dormand–Prince 5(4); rk4: classical RK4 at rk4_dt_s (the study's)
        pub integrator: super::Integrator [default = "adaptive"],
        /// relative tolerance of the adaptive integrator (1e-10: converged on the shared real records,
        /// docs/convergence.md)
        pub rtol: f64 [default = 1e-10, range = (1e-14, 1e-2)],
        /// absolute tolerance on positions (m) and angles (rad); ten times it on velocities (1e-13:
        /// converged while the cart creeps, docs/convergence.md)
        pub atol: f64 [default = 1e-13, unit = "m", range = (1e-16, 1e-2)],
        /// RK4 step (integrator: rk4)
        pub rk4_dt_s: f64 [default = 1e-4, unit = "s", range = (1e-7, 1.0)],
        /// draw a PNG per record like the study's Figure 11
        pub figure: bool [default = true],
        #[flatten]
        pub mcap: super::Mcap,
    }
}

crate::choice! {
    /// `friction_law`.
    pub enum FrictionLawChoice { Regularised = "regularised", StickSlip = "stick_slip" }
}

super::declare_stage! {
    /// Rolling, turning and pivot steering of equipment on four swivel casters under the two horizontal floor
    /// components (the study's 4WMC, made well posed).
    pub struct SimulateRolling: "simulate_rolling", version 3, reads Datasets, params SimulateRollingParams;
    outputs {
        /// on the input time base: time_s, x_m, y_m, yaw_rad, delta1_rad…delta4_rad, velocities, roll1_mps…roll4_mps,
        /// swivel rates, the platform's absolute acceleration ax_abs_mps2/ay_abs_mps2, the floor input
        "trajectory": TimeSeries,
        /// breakaway, rest and caster flip times, the peak displacement and the peak yaw: time_s, event, caster,
        /// displacement_m, yaw_rad, delta_rad
        "events": Table => Rolling,
        /// <partition>.png: floor inputs, x/y displacement, yaw with the four caster angles, and the x–y orbit (the
        /// study's Figure 11)
        "figures": Files,
    }
    examples {
        /// the study's patient bed PB2 on four swivel casters under both horizontal components
        super::RINALDI => "\
simulate_rolling:
  type: simulate_rolling
  inputs: [load]
  params:
    preset: PB2
    x_channel: ax_mps2
    y_channel: ay_mps2
",
    }
}

impl Stage for SimulateRolling {
    super::info_and_check_params!(SimulateRollingParams);

    fn check(&self, params: &Params, base_dir: &Path) -> Result<(), ParamError> {
        Setup::resolve(&params::typed(params)?, base_dir).map(|_| ())
    }

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::EachRecord
    }

    fn summary(&self, stage_dir: &Path) -> Option<String> {
        summary_line(stage_dir).ok()
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: SimulateRollingParams = params::typed(ctx.params)?;
        let setup = Setup::resolve(&p, ctx.base_dir)?;
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        parts.par_iter().try_for_each(|part| {
            let table = ctx.read_table(part)?;
            let record = super::record_title(&part.partition, &part.label);
            let outputs = setup.simulate(&table, &p, &record).map_err(|e| anyhow::anyhow!("{}: {e}", part.label))?;
            let (mut trajectory, mut events, png) = outputs;
            for t in [&mut trajectory, &mut events] {
                t.metadata.extend(super::record_provenance(part));
            }
            ctx.sink.write("trajectory", &part.partition, trajectory)?;
            ctx.sink.write("events", &part.partition, events)?;
            if let Some(png) = png {
                let name = super::figure_stem(&part.partition, &setup.unit);
                ctx.sink.write_file("figures", &format!("{name}.png"), &png)?;
            }
            Ok(())
        })
    }
}

/// The model as the parameters resolve it.
struct Setup {
    unit: String,
    cart: Cart,
    friction: Friction,
    options: Options,
    /// Every model key with the value used (for the metadata).
    resolved: Map<String, Value>,
}

fn refuse(key: &str, message: String, hint: impl Into<String>) -> ParamError {
    ParamError { key: Some(key.to_string()), message, hint: hint.into() }
}

impl Setup {
    fn resolve(params: &SimulateRollingParams, base_dir: &Path) -> Result<Setup, ParamError> {
        let preset = params.preset.as_deref();
        let mut values = match preset {
            Some(name) => table4_values(&rolling::preset(name).expect("the preset was checked against the list")),
            None => RollingModel::default(),
        };
        let equipment = params.equipment.as_deref();
        if let Some(relative) = equipment {
            values = read_equipment(&base_dir.join(relative))?.over(values);
        }
        let m = params.model.clone().over(values);
        let required = |value: Option<f64>, key: &str| {
            value.ok_or_else(|| {
                refuse(
                    key,
                    format!("`simulate_rolling` needs `{key}`"),
                    format!(
                        "set `{key}`, a `preset` ({}) or an `equipment` file that gives it",
                        rolling::PRESETS.join(", ")
                    ),
                )
            })
        };
        let diameter = required(m.wheel_diameter_m, "wheel_diameter_m")?;
        let lateral_slip = params.lateral_slip;
        let cart = Cart {
            length_m: required(m.length_m, "length_m")?,
            width_m: required(m.width_m, "width_m")?,
            platform_mass_kg: required(m.platform_mass_kg, "platform_mass_kg")?,
            wheel_diameter_m: diameter,
            wheel_width_m: required(m.wheel_width_m, "wheel_width_m")?,
            wheel_mass_kg: required(m.wheel_mass_kg, "wheel_mass_kg")?,
            trail_m: m.trail_m.unwrap_or_else(|| Cart::default_trail_m(diameter)),
            swivel_arm_m: m.swivel_arm_m.unwrap_or(rolling::DEFAULT_SWIVEL_ARM_M),
        };
        cart.check(lateral_slip).map_err(|e| {
            let key = e.parameter().unwrap_or("length_m");
            refuse(key, format!("`simulate_rolling`: {e}"), "see `shakeflow stages simulate_rolling`")
        })?;
        let p = m.p.unwrap_or(1.0);
        let (beta, gamma) = (required(m.beta_spm, "beta_spm")?, required(m.gamma_n, "gamma_n")?);
        let stribeck = |s: f64, k: f64| Stribeck { mu_s: s, mu_k: k, beta_spm: beta, gamma_n: gamma, p };
        let law = match params.friction_law {
            FrictionLawChoice::Regularised => FrictionLaw::Regularised,
            FrictionLawChoice::StickSlip => FrictionLaw::StickSlip,
        };
        if lateral_slip && law == FrictionLaw::StickSlip {
            return Err(refuse(
                "friction_law",
                "`simulate_rolling`: the exact stick-slip law needs casters that cannot slip sideways".into(),
                "use `friction_law: regularised` with `lateral_slip: true`",
            ));
        }
        let friction = Friction {
            roll: stribeck(required(m.mu_s_roll, "mu_s_roll")?, required(m.mu_k_roll, "mu_k_roll")?),
            swivel: stribeck(required(m.mu_s_swivel, "mu_s_swivel")?, required(m.mu_k_swivel, "mu_k_swivel")?),
            eps_mps: m.friction_eps.unwrap_or(rolling::DEFAULT_FRICTION_EPS_MPS),
            eps_swivel_radps: m.friction_eps_swivel.unwrap_or(rolling::DEFAULT_FRICTION_EPS_SWIVEL_RADPS),
            law,
        };
        friction.check().map_err(|e| {
            refuse(
                e.parameter().unwrap_or("friction_eps"),
                format!("`simulate_rolling`: {e}"),
                "friction values must be zero or positive, ε positive",
            )
        })?;
        let steer = m.steer0_deg.unwrap_or([0.0; 4]);
        let lateral = lateral_slip.then_some(LateralSlip { mu: params.mu_lateral, eps_mps: params.lateral_eps });
        if let Some(l) = lateral {
            if !(l.mu > 0.0 && l.eps_mps > 0.0) {
                return Err(refuse(
                    "mu_lateral",
                    "`simulate_rolling`: lateral slip needs mu_lateral > 0 and lateral_eps > 0".into(),
                    "e.g. mu_lateral: 0.5, lateral_eps: 0.001",
                ));
            }
        }
        let method = match params.integrator {
            super::Integrator::Rk4 => Method::Rk4 { dt_s: params.rk4_dt_s },
            super::Integrator::Adaptive => Method::Adaptive { rtol: params.rtol, atol: params.atol },
        };
        let options = Options {
            yaw0_rad: m.yaw0_deg.unwrap_or(0.0).to_radians(),
            steer0_rad: steer.map(f64::to_radians),
            lateral_slip: lateral,
            method,
            g_mps2: rolling::G_MPS2,
        };
        let unit = params
            .unit
            .as_deref()
            .or(preset)
            .map(String::from)
            .or_else(|| equipment.and_then(Path::file_stem).map(|s| s.to_string_lossy().into_owned()))
            .unwrap_or_else(|| "cart".into());
        let mut resolved = Map::new();
        resolved.insert("unit".into(), json!(unit));
        for (key, value) in [
            ("length_m", cart.length_m),
            ("width_m", cart.width_m),
            ("platform_mass_kg", cart.platform_mass_kg),
            ("wheel_diameter_m", cart.wheel_diameter_m),
            ("wheel_width_m", cart.wheel_width_m),
            ("wheel_mass_kg", cart.wheel_mass_kg),
            ("yaw0_deg", m.yaw0_deg.unwrap_or(0.0)),
            ("mu_s_roll", friction.roll.mu_s),
            ("mu_s_swivel", friction.swivel.mu_s),
            ("mu_k_roll", friction.roll.mu_k),
            ("mu_k_swivel", friction.swivel.mu_k),
            ("beta_spm", beta),
            ("gamma_n", gamma),
            ("p", p),
            ("trail_m", cart.trail_m),
            ("swivel_arm_m", cart.swivel_arm_m),
            ("friction_eps", friction.eps_mps),
            ("friction_eps_swivel", friction.eps_swivel_radps),
        ] {
            resolved.insert(key.into(), json!(value));
        }
        resolved.insert("steer0_deg".into(), json!(steer));
        resolved.sort_keys();
        Ok(Setup { unit, cart, friction, options, resolved })
    }

    /// Runs the model on one record (`record`: how the figure's title names it).
    fn simulate(
        &self,
        table: &Table,
        params: &SimulateRollingParams,
        record: &str,
    ) -> Result<(Table, Table, Option<Vec<u8>>), StageError> {
        let time = table.f64_column(TIME_COLUMN).ok_or_else(|| StageError::Record("no time_s column".into()))?;
        let column = |name: &str| {
            table.f64_column(name).ok_or_else(|| {
                StageError::Record(format!(
                    "no float column `{name}` (set x_channel / y_channel); columns: {}",
                    table.column_names().join(", ")
                ))
            })
        };
        let (x_name, y_name) = (params.x_channel.as_str(), params.y_channel.as_str());
        let (ax, ay) = (column(x_name)?, column(y_name)?);
        let n = time.len();
        if n < 2 {
            return Err(StageError::Record(format!("{n} sample(s): the simulation needs at least 2")));
        }
        let step = time[1] - time[0];
        if let Some(k) = (1..n).find(|&k| ((time[k] - time[k - 1]) - step).abs() > 1e-6 * step.abs()) {
            return Err(StageError::Record(format!(
                "time is not uniformly sampled: the step at t = {} s is {} s, the record's first step {step} s; resample the record (a source's `non_uniform: resample`)",
                time[k - 1],
                time[k] - time[k - 1]
            )));
        }
        let dt = (time[n - 1] - time[0]) / (n - 1) as f64;
        let excitation = Excitation { t0_s: time[0], dt_s: dt, ax_mps2: ax, ay_mps2: ay };
        let response = simulate(&self.cart, &self.friction, &excitation, &self.options)?;
        let trajectory = self.trajectory(time, ax, ay, &response, x_name, y_name);
        let events = self.events(time, &response);
        let png = if params.figure { Some(self.figure(record, time, ax, ay, &response)?) } else { None };
        Ok((trajectory, events, png))
    }

    fn metadata(&self, response: &Response) -> String {
        let (peak, _) = response.peak_displacement();
        let (yaw, _) = response.peak_yaw();
        let stats = response.stats;
        json!({
            "unit": self.unit,
            "model": self.resolved,
            "friction_law": match self.friction.law { FrictionLaw::Regularised => "regularised", FrictionLaw::StickSlip => "stick_slip" },
            "lateral_slip": self.options.lateral_slip.map(|l| json!({"mu": l.mu, "eps_mps": l.eps_mps})),
            "method": match self.options.method {
                Method::Adaptive { rtol, atol } => json!({"integrator": "adaptive", "rtol": rtol, "atol": atol}),
                Method::Rk4 { dt_s } => json!({"integrator": "rk4", "dt_s": dt_s}),
            },
            "wheel_order": "1 (+a,+b) front left, 2 (-a,+b) rear left, 3 (-a,-b) rear right, 4 (+a,-b) front right",
            "peak_displacement_m": peak,
            "peak_yaw_rad": yaw,
            "caster_flips": response.flips(),
            "steps": {"accepted": stats.accepted, "rejected": stats.rejected, "rhs_evals": stats.rhs_evals},
        })
        .to_string()
    }

    fn trajectory(&self, time: &[f64], ax: &[f64], ay: &[f64], r: &Response, x_name: &str, y_name: &str) -> Table {
        let columns = [
            f64_columns([
                (TIME_COLUMN, "s", "time (the input's time base)", time.to_vec()),
                ("x_m", "m", "platform centre, floor X, from its start", r.x_m.clone()),
                ("y_m", "m", "platform centre, floor Y, from its start", r.y_m.clone()),
                ("yaw_rad", "rad", "platform yaw θ: its length axis from floor X (unwrapped)", r.yaw_rad.clone()),
            ]),
            casters(
                "delta#_rad",
                "rad",
                "caster # steering angle δ from the length axis (unwrapped; 0 trails toward +x)",
                &r.delta_rad,
            ),
            f64_columns([
                ("vx_mps", "m/s", "platform centre velocity, floor X, relative to the floor", r.vx_mps.clone()),
                ("vy_mps", "m/s", "platform centre velocity, floor Y, relative to the floor", r.vy_mps.clone()),
                ("yaw_rate_radps", "rad/s", "platform yaw rate", r.yaw_rate_radps.clone()),
            ]),
            casters("roll#_mps", "m/s", "caster # rolling speed: wheel centre along its heading", &r.roll_speed_mps),
            casters("swivel#_radps", "rad/s", "caster # swivel rate dδ/dt", &r.swivel_rate_radps),
            f64_columns([
                (
                    "ax_abs_mps2",
                    "m/s^2",
                    "absolute acceleration of the platform centre along floor X (E-W): what a top accelerometer on the unit would record",
                    r.ax_abs_mps2.clone(),
                ),
                ("ay_abs_mps2", "m/s^2", "absolute acceleration of the platform centre along floor Y", r.ay_abs_mps2.clone()),
                ("floor_ax_mps2", "m/s^2", &format!("floor acceleration X (input `{x_name}`)"), ax.to_vec()),
                ("floor_ay_mps2", "m/s^2", &format!("floor acceleration Y (input `{y_name}`)"), ay.to_vec()),
            ]),
        ];
        let mut t = Table::new();
        t.extend(columns.into_iter().flatten());
        t.metadata.insert("shakeflow.rolling".into(), self.metadata(r));
        t
    }

    fn events(&self, time: &[f64], r: &Response) -> Table {
        let (x0, y0, yaw0) = (r.x_m[0], r.y_m[0], r.yaw_rad[0]);
        let mut rows: Vec<(f64, &str, i64, [f64; 7])> =
            r.events.iter().map(|e| (e.time_s, e.kind.name(), e.caster.map_or(0, |c| c as i64 + 1), e.pose)).collect();
        let pose_at = |k: usize| -> [f64; 7] {
            [
                r.x_m[k],
                r.y_m[k],
                r.yaw_rad[k],
                r.delta_rad[0][k],
                r.delta_rad[1][k],
                r.delta_rad[2][k],
                r.delta_rad[3][k],
            ]
        };
        let (_, k_disp) = r.peak_displacement();
        let (_, k_yaw) = r.peak_yaw();
        rows.push((time[k_disp], "peak_displacement", 0, pose_at(k_disp)));
        rows.push((time[k_yaw], "peak_yaw", 0, pose_at(k_yaw)));
        let mut t = Table::new();
        t.push(Column::f64(
            TIME_COLUMN,
            "s",
            "when (events located on the integrator's continuous output; peaks at samples)",
            rows.iter().map(|r| r.0).collect(),
        ));
        t.push(Column {
            name: "event".into(),
            unit: String::new(),
            description: "breakaway (starts to move: leaves exact rest, or first exceeds 1 mm/s), rest (sticks; stick_slip only), flip (a caster swings past 135° from the direction it trailed), peak_displacement, peak_yaw".into(),
            data: ColumnData::Str(rows.iter().map(|r| r.1.to_string()).collect()),
        });
        t.push(Column {
            name: "caster".into(),
            unit: String::new(),
            description: "caster 1-4 (wheel order of steer0_deg) for flips; 0 for the whole cart".into(),
            data: ColumnData::I64(rows.iter().map(|r| r.2).collect()),
        });
        t.push(Column::f64(
            "displacement_m",
            "m",
            "distance of the platform centre from its start",
            rows.iter().map(|r| (r.3[0] - x0).hypot(r.3[1] - y0)).collect(),
        ));
        t.push(Column::f64(
            "yaw_rad",
            "rad",
            "platform yaw change θ − θ₀",
            rows.iter().map(|r| r.3[2] - yaw0).collect(),
        ));
        t.push(Column {
            name: "delta_rad".into(),
            unit: "rad".into(),
            description: "the caster's steering angle δ at a flip (null for whole-cart events)".into(),
            data: ColumnData::OptF64(rows.iter().map(|r| (r.2 > 0).then(|| r.3[2 + r.2 as usize])).collect()),
        });
        t.metadata.insert("shakeflow.rolling".into(), self.metadata(r));
        t
    }

    fn figure(
        &self,
        record: &str,
        time: &[f64],
        ax: &[f64],
        ay: &[f64],
        r: &Response,
    ) -> Result<Vec<u8>, crate::plot::PlotError> {
        use crate::plot::{render_png_with_side, unwrap_degrees, Marker, Panel, Series};
        // Casters swivel through whole turns: unwrapped, a turn past ±180° is no jump.
        let degrees = |v: &[f64]| unwrap_degrees(&v.iter().map(|x| x.to_degrees()).collect::<Vec<f64>>());
        let yaw = degrees(&r.yaw_rad);
        let deltas: Vec<Vec<f64>> = r.delta_rad.iter().map(|d| degrees(d)).collect();
        let flips: Vec<Marker> = r
            .events
            .iter()
            .filter(|e| e.kind == EventKind::Flip)
            .map(|e| Marker { x: e.time_s, label: format!("{}", e.caster.map_or(0, |c| c + 1)) })
            .collect();
        let breakaway: Vec<Marker> = r
            .events
            .iter()
            .filter(|e| e.kind == EventKind::Breakaway)
            .take(1)
            .map(|e| Marker { x: e.time_s, label: "breakaway".into() })
            .collect();
        let wheel = ["δ1 front left", "δ2 rear left", "δ3 rear right", "δ4 front right"];
        let mut angle_series = vec![Series::new("θ platform", time, &yaw)];
        for (i, d) in deltas.iter().enumerate() {
            angle_series.push(Series::new(wheel[i], time, d));
        }
        let panels = [
            Panel {
                title: "floor acceleration (input)".into(),
                x_label: "time [s]".into(),
                y_label: "[m/s^2]".into(),
                series: vec![Series::new("X (E-W)", time, ax), Series::new("Y (N-S)", time, ay)],
                markers: breakaway,
                log_y: false,
                spans: Vec::new(),
            },
            Panel {
                title: "platform displacement relative to the floor".into(),
                x_label: "time [s]".into(),
                y_label: "[m]".into(),
                series: vec![Series::new("x", time, &r.x_m), Series::new("y", time, &r.y_m)],
                markers: Vec::new(),
                log_y: false,
                spans: Vec::new(),
            },
            Panel {
                title: "platform yaw and caster steering angles, unwrapped (dashed: caster flips, by caster)".into(),
                x_label: "time [s]".into(),
                y_label: "[deg]".into(),
                series: angle_series,
                markers: flips,
                log_y: false,
                spans: Vec::new(),
            },
        ];
        let orbit = Panel {
            title: "x–y orbit of the platform centre".into(),
            x_label: "x [m]".into(),
            y_label: "y [m]".into(),
            series: vec![Series::new(String::new(), &r.x_m, &r.y_m)],
            markers: Vec::new(),
            log_y: false,
            spans: Vec::new(),
        };
        let (peak, _) = r.peak_displacement();
        let (peak_yaw, _) = r.peak_yaw();
        let title = format!(
            "{} on unlocked casters under {record}: peak displacement {:.3} m, peak yaw {:.1}°, caster flips {:?}",
            self.unit,
            peak,
            peak_yaw.to_degrees(),
            r.flips()
        );
        render_png_with_side(&title, &panels, &orbit, 600, 1700, 1100)
    }
}

/// A Table 4 row as model-key values.
fn table4_values(row: &rolling::Table4) -> RollingModel {
    RollingModel {
        length_m: Some(row.length_m),
        width_m: Some(row.width_m),
        platform_mass_kg: Some(row.platform_mass_kg),
        wheel_diameter_m: Some(row.wheel_diameter_m),
        wheel_width_m: Some(row.wheel_width_m),
        wheel_mass_kg: Some(row.wheel_mass_kg),
        yaw0_deg: Some(row.yaw0_deg),
        steer0_deg: Some(row.steer0_deg),
        mu_s_roll: Some(row.mu_s_roll),
        mu_s_swivel: Some(row.mu_s_swivel),
        mu_k_roll: Some(row.mu_k_roll),
        mu_k_swivel: Some(row.mu_k_swivel),
        beta_spm: Some(row.beta_spm),
        gamma_n: Some(row.gamma_n),
        p: Some(row.p),
        ..RollingModel::default()
    }
}

/// An equipment file: a YAML mapping of model keys, checked like stage parameters. Errors name
/// the file and the line of the offending key.
fn read_equipment(path: &Path) -> Result<RollingModel, ParamError> {
    let normal = crate::pipeline::spec::lexically_normal(path);
    let shown = normal.display();
    let hint = format!(
        "an equipment file holds model keys only: {}",
        RollingModel::specs().iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
    );
    let text = std::fs::read_to_string(path)
        .map_err(|e| refuse("equipment", format!("cannot read the equipment file `{shown}`: {e}"), hint.clone()))?;
    let yaml: serde_yaml::Value = serde_yaml::from_str(&text).map_err(|e| {
        let at = e.location().map(|l| format!(":{}:{}", l.line(), l.column())).unwrap_or_default();
        refuse("equipment", format!("equipment file `{shown}`{at}: not valid YAML: {e}"), hint.clone())
    })?;
    let Some(mapping) = yaml.as_mapping() else {
        return Err(refuse("equipment", format!("equipment file `{shown}`: expected a mapping of model keys"), hint));
    };
    let mut given = Vec::new();
    for (key, value) in mapping {
        let Some(key) = key.as_str() else {
            return Err(refuse(
                "equipment",
                format!("equipment file `{shown}`: keys must be text, found {key:?}"),
                hint,
            ));
        };
        given.push((key.to_string(), params::yaml_to_json(value)));
    }
    let normalized =
        params::normalize(RollingModel::specs(), "equipment file", given.iter().map(|(k, v)| (k.as_str(), v.clone())))
            .map_err(|e| {
                let at = e
                    .key
                    .as_deref()
                    .and_then(|k| crate::pipeline::locate::key_position(&text, &[k]))
                    .map(|(l, c)| format!(":{l}:{c}"))
                    .unwrap_or_default();
                let message =
                    e.message.replace(" for stage type `equipment file`", "").replace(" of `equipment file`", "");
                refuse("equipment", format!("equipment file `{shown}`{at}: {message}"), e.hint)
            })?;
    params::typed(&normalized)
}

/// The line `shakeflow run` prints: "10 records: peak displacement 0.412 m (FB-4), started rolling in 9, 14 caster flips"
fn summary_line(dir: &Path) -> anyhow::Result<String> {
    let events = summary::read(dir, "events")?;
    let (records, kinds) = (events.record_labels()?, summary::texts(&events.frame, "event")?);
    let displacement = summary::floats(&events.frame, "displacement_m")?;
    let mut peak: Option<(f64, &str)> = None;
    let mut rolled = std::collections::BTreeSet::new();
    for ((kind, record), d) in kinds.iter().zip(&records).zip(&displacement) {
        match kind.as_str() {
            "peak_displacement" => {
                if let Some(d) = d.filter(|d| peak.is_none_or(|(p, _)| *d > p)) {
                    peak = Some((d, record));
                }
            }
            "breakaway" => {
                rolled.insert(record);
            }
            _ => {}
        }
    }
    let all: std::collections::BTreeSet<&String> = records.iter().collect();
    let flips = kinds.iter().filter(|k| *k == "flip").count();
    let mut line = format!("{} records", all.len());
    if let Some((d, record)) = peak {
        line += &format!(": peak displacement {d:.3} m");
        if !record.is_empty() {
            line += &format!(" ({record})");
        }
    }
    line += &format!(", started rolling in {}, {flips} caster flips", rolled.len());
    Ok(line)
}

/// A column per caster, 1 to 4: `#` in the name and description is the caster's number.
fn casters(name: &str, unit: &str, description: &str, values: &[Vec<f64>; 4]) -> Vec<Column> {
    let numbered = |text: &str, i: usize| text.replace('#', &(i + 1).to_string());
    let column = |(i, values): (usize, &Vec<f64>)| {
        Column::f64(&numbered(name, i), unit, &numbered(description, i), values.clone())
    };
    values.iter().enumerate().map(column).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(given: Value) -> SimulateRollingParams {
        let given = given.as_object().unwrap().clone();
        params::typed(
            &params::normalize(INFO.params, INFO.name, given.iter().map(|(k, v)| (k.as_str(), v.clone()))).unwrap(),
        )
        .unwrap()
    }

    /// An equipment file is read as `RollingModel`: its fields are exactly the model keys.
    #[test]
    fn the_model_struct_is_the_model_keys() {
        let none = params::normalize(RollingModel::specs(), "equipment file", []).unwrap();
        params::check_typed::<RollingModel>(&none).unwrap();
        let given = [("steer0_deg", json!([80, 0, 0, 80])), ("p", json!(2))];
        let some = params::normalize(RollingModel::specs(), "equipment file", given).unwrap();
        params::check_typed::<RollingModel>(&some).unwrap();
        assert_eq!(params::typed::<RollingModel>(&some).unwrap().steer0_deg, Some([80.0, 0.0, 0.0, 80.0]));
    }

    #[test]
    fn layers_resolve_preset_then_file_then_stage_values() {
        let dir = crate::tempdir::tempdir().unwrap();
        std::fs::write(dir.path().join("mc2.yaml"), "# heavier\nplatform_mass_kg: 200\ntrail_m: 0.05\n").unwrap();
        let setup =
            Setup::resolve(&params(json!({"preset": "MC2", "equipment": "mc2.yaml", "trail_m": 0.04})), dir.path())
                .unwrap();
        assert_eq!(setup.cart.platform_mass_kg, 200.0, "the file overrides the preset");
        assert_eq!(setup.cart.trail_m, 0.04, "the stage's value overrides the file");
        assert_eq!(setup.cart.length_m, 0.65, "the preset fills the rest");
        assert_eq!(setup.friction.roll.mu_s, 0.044);
        assert_eq!(setup.unit, "MC2");
        let plain = Setup::resolve(&params(json!({"preset": "PS1"})), dir.path()).unwrap();
        assert_eq!(plain.cart.trail_m, 0.06, "default trail 0.3 × 0.20 m");
        assert_eq!(plain.options.steer0_rad[0], 80f64.to_radians());
    }

    #[test]
    fn missing_values_and_bad_files_are_named() {
        let dir = crate::tempdir::tempdir().unwrap();
        let err = Setup::resolve(&params(json!({})), dir.path()).err().unwrap();
        assert!(err.message.contains("needs `wheel_diameter_m`") && err.hint.contains("preset"), "{err:?}");
        std::fs::write(dir.path().join("bad.yaml"), "length_m: 1.0\nlenght_m: 2.0\n").unwrap();
        let err = Setup::resolve(&params(json!({"preset": "UI3", "equipment": "bad.yaml"})), dir.path()).err().unwrap();
        assert_eq!(err.key.as_deref(), Some("equipment"));
        assert!(
            err.message.contains("bad.yaml`:2:1: unknown parameter `lenght_m`") && err.hint.contains("length_m"),
            "{err:?}"
        );
        let err = Setup::resolve(&params(json!({"preset": "UI3", "trail_m": 0.0})), dir.path()).err().unwrap();
        assert_eq!(err.key.as_deref(), Some("trail_m"));
        assert!(err.message.contains("lateral_slip"), "{err:?}");
        assert!(
            Setup::resolve(&params(json!({"preset": "UI3", "trail_m": 0.0, "lateral_slip": true})), dir.path()).is_ok()
        );
    }

    /// The one line after `run`: the peak displacement and its record, breakaways and flips.
    #[test]
    fn the_summary_line_names_the_peak_and_counts_breakaways_and_flips() {
        use crate::stages::test_tables::{part, text};
        let dir = crate::tempdir::tempdir().unwrap();
        let events =
            |kinds: &[&str], d: &[f64]| vec![text("event", kinds), Column::f64("displacement_m", "m", "d", d.to_vec())];
        part(
            dir.path(),
            "events",
            "motion=FB-1",
            events(&["breakaway", "flip", "peak_displacement"], &[0.0, 0.1, 0.25]),
        );
        part(dir.path(), "events", "motion=FB-2", events(&["peak_displacement"], &[0.0]));
        assert_eq!(
            SimulateRolling.summary(dir.path()).unwrap(),
            "2 records: peak displacement 0.250 m (FB-1), started rolling in 1, 1 caster flips"
        );
    }
}
