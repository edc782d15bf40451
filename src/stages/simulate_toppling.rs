//! `simulate_toppling`: the study's 2D rigid-block model (rest, rocking, impacts, overturning)
//! driven by floor records: θ(t), θ̇(t) and what a top accelerometer would record, the events,
//! and a figure per record.

use super::error::{float_column, StageError};
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::{f64_columns, Stage, StageContext};
use crate::error::UserError;
use crate::io::equipment::{self, RockingGeometry, ShapeChoice};
use crate::physics::rocking::{self, Anchorage, Block, Excitation, IsolatedBase, Method, Options, Response, Shape};
use crate::pipeline::params::{self, ParamError, ParamKind, Params};
use crate::summary;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The parameters that describe the unit and the model, shared with `toppling_fragility`
    /// (flattened into each stage's parameters).
    pub struct RockingParams {
        // A row of `rocking::PRESETS` (the table is the list, so it stays a name).
        /// a unit of the study (Table 5 rectangles PS2, PB1 and their trapezoids; WSU1 from Table 2)
        pub preset: Option<String> [default = null, kind = ParamKind::Choice(crate::physics::rocking::PRESETS)],
        /// a YAML file with shape, B_m, H_m, f, mass_kg (B1_m, B2_m), like the cases' equipment.yaml; overrides the
        /// preset
        pub equipment: Option<PathBuf> [default = null],
        #[flatten]
        pub geometry: RockingGeometry,
        /// input column: in-plane horizontal floor acceleration (m/s^2)
        pub horizontal: String [default = "ax_mps2"],
        /// input column: vertical floor acceleration (m/s^2, up); null: none
        pub vertical: Option<String> [default = null],
        /// coefficient of restitution; null: Eq. 24, e = 1 - (mRB/I0) sin(alpha)
        pub restitution: Option<f64> [default = null, range = (0.0, 1.0)],
        /// tension anchors at both base corners, strength F/W; null: free-standing
        pub anchor_strength: Option<f64> [default = null, range = (1e-6, 100.0)],
        /// anchor elongation at fracture over elongation at yield (mu)
        pub anchor_ductility: f64 [default = 5.0, range = (1.0, 1e3)],
        /// block rotation at which a slack anchor yields (sets the anchor stiffness)
        pub anchor_yield_rotation_rad: f64 [default = 0.001, unit = "rad", range = (1e-7, 0.5)],
        /// linear isolated base under the block (period T_b); null: on the floor
        pub isolation_period_s: Option<f64> [default = null, unit = "s", range = (1e-3, 100.0)],
        /// damping ratio of the isolated base
        pub isolation_damping: f64 [default = 0.1, range = (0.0, 0.99)],
        /// isolated base: its mass over the block's, m_b/m; the base carries the block's reaction and impacts
        /// conserve the system's momentum (docs/models/toppling.md); null: the limit m_b >> m, a prescribed base
        /// motion
        pub isolation_mass_ratio: Option<f64> [default = null, range = (1e-6, 1e9)],
        /// height of the top accelerometer; null: the top of the block
        pub sensor_height_m: Option<f64> [default = null, unit = "m", range = (0.0, 1e3)],
        /// adaptive Dormand-Prince 5(4) with located events, or the study's fixed-step RK4
        pub method: super::Integrator [default = "adaptive"],
        /// relative tolerance of the adaptive integrator (absolute: 1e-2 rtol rad)
        pub rtol: f64 [default = 1e-11, range = (1e-14, 1e-2)],
        /// RK4 step (the study's 1e-4 s)
        pub rk4_dt_s: f64 [default = 0.0001, unit = "s", range = (1e-7, 0.1)],
        /// an impact whose rebound would rock the block less than this (free rocking) puts it back at rest
        pub rest_amplitude_rad: f64 [default = 1e-7, unit = "rad", range = (0.0, 0.1)],
    }
}

crate::stage_params! {
    /// The parameters of `simulate_toppling`.
    pub struct SimulateTopplingParams {
        #[flatten]
        pub model: RockingParams,
        /// initial rotation (free-rocking tests); 0: at rest
        pub initial_theta_rad: f64 [default = 0.0, unit = "rad", range = (-1.5, 1.5)],
        // Draw the PNG per record (`report` links it when it was drawn).
        /// draw a PNG per record (floor and top acceleration, θ with the events); false: tables only, as a script
        /// calling the stage per record wants
        pub figure: bool [default = true],
        #[flatten]
        pub mcap: super::Mcap,
    }
}

super::declare_stage! {
    /// The study's 2D rigid-block toppling model on floor records: rest, uplift (Eq. 20/21), rocking (Eq. 22), impacts
    /// (Eq. 24), overturning; adaptive integration with located events.
    pub struct SimulateToppling: "simulate_toppling", version 3, reads Datasets, params SimulateTopplingParams;
    outputs {
        /// per record: time_s, theta_rad, theta_dot_radps, top_ax_mps2 (what a top accelerometer records), on the input
        /// time base
        "response": TimeSeries,
        /// per record: uplifts, impacts, returns to rest, anchor yield/fracture, overturn; the last row (event =
        /// summary) and every row carry overturned, overturn_time_s, overturn_side
        "events": Table => Rocking,
        /// <record>.png: floor and top acceleration, theta with the events marked
        "figures": Files,
    }
    examples {
        /// the study's PS2 unit on the baseline-corrected record, both horizontal and vertical shaking
        super::RINALDI => "\
baseline:
  type: baseline
  inputs: [load]
simulate_toppling:
  type: simulate_toppling
  inputs: [baseline]
  params:
    preset: PS2
    horizontal: ax_mps2
    vertical: az_mps2
",
    }
}

impl Stage for SimulateToppling {
    super::info_and_check_params!(SimulateTopplingParams);

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::EachRecord
    }

    /// `horizontal` and `vertical` must be columns of the floor records.
    fn output_columns(&self, params: &Params, input: Option<&[String]>) -> super::ColumnCheck {
        (None, floor_column_errors(params, input))
    }

    fn summary(&self, stage_dir: &Path) -> Option<String> {
        summary_line(stage_dir).ok()
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: SimulateTopplingParams = params::typed(ctx.params)?;
        let equipment = p.model.equipment.as_deref().map(|e| ctx.file_path(e));
        let (block, mut options) = model_from_params(&p.model, equipment.as_deref())?;
        options.initial_theta_rad = p.initial_theta_rad;
        let columns = (p.model.horizontal.as_str(), p.model.vertical.as_deref());
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        parts.par_iter().try_for_each(|part| {
            let table = ctx.read_table(part)?;
            let (floor, response) = simulate_record(&table, &block, &options, columns.0, columns.1)
                .map_err(|e| anyhow::anyhow!("{}: {e}", part.label))?;
            let mut series = response_table(&floor, &response);
            let mut events = events_table(&response);
            let facts = model_facts(&block, &options).to_string();
            for t in [&mut series, &mut events] {
                t.metadata.extend(super::record_provenance(part));
                t.metadata.insert("shakeflow.rocking".into(), facts.clone());
            }
            if p.figure {
                let name = super::figure_stem(&part.partition, "response");
                let title = format!(
                    "{}: rocking model under {}",
                    unit_name(&p.model, ctx.stage_name),
                    super::record_title(&part.partition, &part.label)
                );
                let png = figure(&title, &floor, &response).map_err(anyhow::Error::msg)?;
                ctx.sink.write_file("figures", &format!("{name}.png"), &png)?;
            }
            ctx.sink.write("events", &part.partition, events)?;
            ctx.sink.write("response", &part.partition, series)
        })
    }
}

/// The floor a record provides: its time base and the chosen channels.
pub struct Floor {
    pub time: Vec<f64>,
    pub horizontal: Vec<f64>,
    pub vertical: Option<Vec<f64>>,
}

/// Reads the floor channels of a record and runs the model.
pub fn simulate_record(
    table: &Table,
    block: &Block,
    options: &Options,
    horizontal: &str,
    vertical: Option<&str>,
) -> Result<(Floor, Response), StageError> {
    let column = |name: &str| float_column(table, name).map(<[f64]>::to_vec);
    let time = column(TIME_COLUMN)?;
    if time.len() < 2 {
        return Err(StageError::Record("the record has fewer than 2 samples".into()));
    }
    let dt = crate::table::uniform_step(&time).map_err(|i| {
        StageError::Record(format!("time is not uniformly sampled after t = {} s; resample it first", time[i]))
    })?;
    let floor = Floor { horizontal: column(horizontal)?, vertical: vertical.map(column).transpose()?, time };
    let excitation = Excitation {
        t0_s: floor.time[0],
        dt_s: dt,
        horizontal_mps2: &floor.horizontal,
        vertical_mps2: floor.vertical.as_deref(),
    };
    let response = rocking::simulate(block, &excitation, options)?;
    Ok((floor, response))
}

/// The block and model options from the parameters: a preset, then an equipment file, then
/// the explicit geometry parameters, each overriding the one before.
pub fn model_from_params(p: &RockingParams, equipment_file: Option<&Path>) -> Result<(Block, Options), UserError> {
    let mut geometry = RockingGeometry::default();
    if let Some(name) = &p.preset {
        let (shape, mass) = rocking::preset(name).expect("presets are checked as a choice");
        geometry.mass_kg = Some(mass);
        match shape {
            Shape::Rectangular { b_m, h_m, f } => {
                (geometry.shape, geometry.b_m, geometry.h_m, geometry.f) =
                    (Some(ShapeChoice::Rectangular), Some(b_m), Some(h_m), Some(f));
            }
            Shape::Trapezoidal { b1_m, b2_m, h_m } => {
                (geometry.shape, geometry.b1_m, geometry.b2_m, geometry.h_m) =
                    (Some(ShapeChoice::Trapezoidal), Some(b1_m), Some(b2_m), Some(h_m));
            }
        }
    }
    if let Some(path) = equipment_file {
        geometry = equipment::read_rocking_equipment(path)?.geometry.over(geometry);
    }
    let geometry = p.geometry.clone().over(geometry);
    let missing = |key: &str| {
        UserError::new(format!("the block needs `{key}`")).hint(
            "set `preset`, an `equipment` file, or the geometry parameters (see `shakeflow stages simulate_toppling`)",
        )
    };
    let shape = match geometry.shape {
        Some(ShapeChoice::Rectangular) => Shape::Rectangular {
            b_m: geometry.b_m.ok_or_else(|| missing("B_m"))?,
            h_m: geometry.h_m.ok_or_else(|| missing("H_m"))?,
            f: geometry.f.unwrap_or(0.0),
        },
        Some(ShapeChoice::Trapezoidal) => Shape::Trapezoidal {
            b1_m: geometry.b1_m.ok_or_else(|| missing("B1_m"))?,
            b2_m: geometry.b2_m.ok_or_else(|| missing("B2_m"))?,
            h_m: geometry.h_m.ok_or_else(|| missing("H_m"))?,
        },
        None => return Err(missing("shape")),
    };
    let mass = geometry.mass_kg.unwrap_or(1.0);
    let g = geometry.g_mps2.unwrap_or(crate::units::G0);
    let block = Block::new(shape, mass, g).map_err(|e| UserError::new(format!("invalid block: {e}")))?;
    let options = Options {
        restitution: p.restitution,
        anchorage: p.anchor_strength.map(|strength_ratio| Anchorage {
            strength_ratio,
            ductility: p.anchor_ductility,
            yield_rotation_rad: p.anchor_yield_rotation_rad,
        }),
        isolated_base: p.isolation_period_s.map(|period_s| IsolatedBase {
            period_s,
            damping_ratio: p.isolation_damping,
            mass_ratio: p.isolation_mass_ratio,
        }),
        sensor_height_m: p.sensor_height_m,
        rest_amplitude_rad: p.rest_amplitude_rad,
        method: match p.method {
            super::Integrator::Rk4 => Method::Rk4 { dt_s: p.rk4_dt_s },
            super::Integrator::Adaptive => Method::Adaptive { rtol: p.rtol, atol_rad: 1e-2 * p.rtol },
        },
        ..Options::default()
    };
    Ok((block, options))
}

/// The unit a rocking stage models, as titles name it: its preset, else the stage's name.
pub fn unit_name<'a>(p: &'a RockingParams, stage: &'a str) -> &'a str {
    p.preset.as_deref().unwrap_or(stage)
}

/// The derived quantities a reader needs to interpret the results (artifact metadata).
pub fn model_facts(block: &Block, options: &Options) -> serde_json::Value {
    serde_json::json!({
        "shape": format!("{:?}", block.shape),
        "mass_kg": block.mass_kg,
        "g_mps2": block.g_mps2,
        "alpha_rad": block.alpha_rad,
        "R_m": block.r_m,
        "cm_height_m": block.cm_height_m,
        "I0_per_kg_m2": block.i0_per_kg,
        "p_radps": block.p_radps,
        "restitution_eq24": block.restitution_eq24,
        "restitution_used": options.restitution.unwrap_or(block.restitution_eq24),
        "uplift_threshold_mps2": block.uplift_threshold_mps2(0.0),
        "lie_angle_rad": block.lie_angle_rad,
        "sign_convention": "theta > 0: rotation about the +x base corner, top moving toward +x",
        "options": format!("{options:?}"),
    })
}

fn response_table(floor: &Floor, r: &Response) -> Table {
    let mut t = Table::new();
    t.extend(f64_columns([
        (TIME_COLUMN, "s", "time", floor.time.clone()),
        ("theta_rad", "rad", "rocking angle (> 0: about the +x corner, top toward +x)", r.theta_rad.clone()),
        ("theta_dot_radps", "rad/s", "angular velocity", r.theta_dot_radps.clone()),
        ("theta_ddot_radps2", "rad/s^2", "angular acceleration", r.theta_ddot_radps2.clone()),
        (
            "top_ax_mps2",
            "m/s^2",
            "absolute horizontal acceleration at the top sensor (what a top accelerometer records); after an overturn the sensor lies along the vertical and reads the floor's vertical acceleration",
            r.top_ax_mps2.clone(),
        ),
        (
            "base_ax_mps2",
            "m/s^2",
            "horizontal acceleration under the block (the floor, or the isolated base)",
            r.base_ax_mps2.clone(),
        ),
    ]));
    t
}

fn events_table(r: &Response) -> Table {
    let overturned = r.overturn.is_some();
    let (overturn_time, overturn_side) = r.overturn.map_or((None, 0), |(t, s)| (Some(t), i64::from(s)));
    let mut time: Vec<Option<f64>> = r.events.iter().map(|e| Some(e.time_s)).collect();
    let mut kind: Vec<String> = r.events.iter().map(|e| e.kind.name().to_string()).collect();
    let mut side: Vec<i64> = r.events.iter().map(|e| i64::from(e.side)).collect();
    let mut before: Vec<Option<f64>> = r.events.iter().map(|e| Some(e.theta_dot_before)).collect();
    let mut after: Vec<Option<f64>> = r.events.iter().map(|e| Some(e.theta_dot_after)).collect();
    time.push(overturn_time);
    kind.push("summary".into());
    side.push(overturn_side);
    before.push(None);
    after.push(None);
    let rows = time.len();
    let count = |k| r.count(k) as i64;
    let optional = |name: &str, unit: &str, description: &str, data: Vec<Option<f64>>| Column {
        name: name.into(),
        unit: unit.into(),
        description: description.into(),
        data: ColumnData::OptF64(data),
    };
    let mut t = Table::new();
    t.push(optional(TIME_COLUMN, "s", "time of the event (summary row: the overturn time, null when none)", time));
    t.push(Column {
        name: "event".into(),
        unit: String::new(),
        description: "uplift | impact | rest | anchor_yield | anchor_fracture | overturn | summary".into(),
        data: ColumnData::Str(kind),
    });
    t.push(Column {
        name: "side".into(),
        unit: String::new(),
        description: "sign of theta after the event (the pivot corner); for overturn and summary, the side it fell to"
            .into(),
        data: ColumnData::I64(side),
    });
    t.push(optional("theta_dot_before_radps", "rad/s", "angular velocity just before", before));
    t.push(optional("theta_dot_after_radps", "rad/s", "angular velocity just after (impacts: e times before)", after));
    t.push(Column {
        name: "overturned".into(),
        unit: String::new(),
        description: "the block overturned in this record (same on every row)".into(),
        data: ColumnData::Bool(vec![overturned; rows]),
    });
    t.push(optional(
        "overturn_time_s",
        "s",
        "when it reached the lying angle (null when it did not overturn)",
        vec![overturn_time; rows],
    ));
    t.push(Column {
        name: "overturn_side".into(),
        unit: String::new(),
        description: "+1 / -1: the sign of theta it overturned to; 0 when it did not".into(),
        data: ColumnData::I64(vec![overturn_side; rows]),
    });
    t.push(Column::f64("max_abs_theta_rad", "rad", "largest |theta| in the record", vec![r.max_abs_theta(); rows]));
    t.push(Column {
        name: "n_impacts".into(),
        unit: String::new(),
        description: "impacts in the record".into(),
        data: ColumnData::I64(vec![count(rocking::EventKind::Impact); rows]),
    });
    t.push(Column {
        name: "n_uplifts".into(),
        unit: String::new(),
        description: "uplifts from rest in the record".into(),
        data: ColumnData::I64(vec![count(rocking::EventKind::Uplift); rows]),
    });
    t
}

fn figure(title: &str, floor: &Floor, r: &Response) -> Result<Vec<u8>, crate::plot::PlotError> {
    use crate::plot::{render_png, Marker, Panel, Series};
    let mut markers: Vec<Marker> = r
        .events
        .iter()
        .filter(|e| matches!(e.kind, rocking::EventKind::Uplift | rocking::EventKind::Overturn))
        .take(12)
        .map(|e| Marker { x: e.time_s, label: e.kind.name().into() })
        .collect();
    if let Some(first_impact) = r.events.iter().find(|e| e.kind == rocking::EventKind::Impact) {
        markers.push(Marker { x: first_impact.time_s, label: "first impact".into() });
    }
    let panels = [
        Panel {
            title: "floor and top accelerometer".into(),
            x_label: "time [s]".into(),
            y_label: "acceleration [m/s^2]".into(),
            series: vec![
                Series::new("floor horizontal", &floor.time, &floor.horizontal),
                Series::new("top (model)", &floor.time, &r.top_ax_mps2).model(),
            ],
            markers: Vec::new(),
            log_y: false,
            spans: Vec::new(),
        },
        Panel {
            title: match r.overturn {
                Some((t, s)) => format!("rocking angle: overturned to side {s:+} at {t:.3} s"),
                None => format!("rocking angle: no overturn, max |theta| {:.4} rad", r.max_abs_theta()),
            },
            x_label: "time [s]".into(),
            y_label: "theta [rad]".into(),
            series: vec![Series::new("theta", &floor.time, &r.theta_rad)],
            markers,
            log_y: false,
            spans: Vec::new(),
        },
    ];
    render_png(title, &panels, 1200, 800)
}

/// The floor columns the rocking stages read (`horizontal`, `vertical`) that `input` lacks.
pub fn floor_column_errors(params: &Params, input: Option<&[String]>) -> Vec<ParamError> {
    let Some(input) = input else { return Vec::new() };
    let p: RockingParams = match params::typed(params) {
        Ok(p) => p,
        Err(e) => return vec![e],
    };
    let wanted = [("horizontal", Some(p.horizontal.as_str())), ("vertical", p.vertical.as_deref())];
    wanted.into_iter().filter_map(|(key, column)| super::require_column(key, column?, input).err()).collect()
}

/// The line `shakeflow run` prints: "overturned in 2 of 12 records (FB-5, FB-6)"
fn summary_line(dir: &Path) -> anyhow::Result<String> {
    let events = summary::read(dir, "events")?;
    let (records, kinds) = (events.record_labels()?, summary::texts(&events.frame, "event")?);
    let overturned = summary::flags(&events.frame, "overturned")?;
    let summaries: Vec<usize> = (0..kinds.len()).filter(|&i| kinds[i] == "summary").collect();
    let which: Vec<String> = summaries.iter().filter(|&&i| overturned[i]).map(|&i| records[i].clone()).collect();
    let mut line = format!("overturned in {} of {} records", which.len(), summaries.len());
    if !which.is_empty() {
        line += &format!(" ({})", summary::some_of(&which, 6));
    }
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_block_on_a_ramped_floor_uplifts_when_the_floor_reaches_g_b_over_h() {
        // B/H = 1/3 with the centre of mass at mid-height (f = 0): Housner's threshold g tan α = g B/H.
        let (b, h, g) = (0.5, 1.5, 9.80665);
        let block = Block::new(Shape::Rectangular { b_m: b, h_m: h, f: 0.0 }, 100.0, g).unwrap();
        let rate = 0.5; // m/s² per s
        let n = 2001; // 10 s at 200 Hz
        let time: Vec<f64> = (0..n).map(|k| k as f64 / 200.0).collect();
        let mut table = Table::new();
        table.push(Column::f64(TIME_COLUMN, "s", "", time.clone()));
        table.push(Column::f64("ax_mps2", "m/s^2", "", time.iter().map(|t| rate * t).collect()));
        let (_, response) = simulate_record(&table, &block, &Options::default(), "ax_mps2", None).unwrap();
        let events = events_table(&response);
        let ColumnData::Str(kind) = &events.column("event").unwrap().data else { panic!("event") };
        let ColumnData::OptF64(at) = &events.column(TIME_COLUMN).unwrap().data else { panic!("time_s") };
        assert_eq!(kind[0], "uplift");
        let exact = g * b / h / rate;
        assert!((at[0].unwrap() - exact).abs() < 1e-6, "uplift at {:?} s, closed form {exact} s", at[0]);
        // A floor accelerating toward +x throws the block onto its −x corner.
        let ColumnData::I64(side) = &events.column("side").unwrap().data else { panic!("side") };
        assert_eq!(side[0], -1);
        assert_eq!(kind.last().unwrap(), "summary");
    }

    /// The one line after `run` counts the `summary` rows only.
    #[test]
    fn the_summary_line_counts_the_summary_rows_only() {
        use crate::stages::test_tables::{flag, part, text};
        let dir = crate::tempdir::tempdir().unwrap();
        let kinds = ["uplift", "impact", "overturn", "summary"];
        part(dir.path(), "events", "record=A", vec![text("event", &kinds), flag("overturned", &[true; 4])]);
        part(dir.path(), "events", "record=B", vec![text("event", &["summary"]), flag("overturned", &[false])]);
        assert_eq!(SimulateToppling.summary(dir.path()).unwrap(), "overturned in 1 of 2 records (A)");
    }
}
