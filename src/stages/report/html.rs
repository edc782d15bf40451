//! The study report as one HTML page (`<output_dir>/<report stage>/index.html`): what `report`
//! gathered from its inputs, rendered without scripts, styles from elsewhere or anything from the
//! network. Figures are `<img>`s with relative links to the PNGs of the stages that drew them.
//! Every text that comes from data (unit names, explanations, parameters) is escaped; the bytes
//! depend on the inputs only (no dates, no absolute paths).

use std::fmt::Write;

/// Everything the page shows, in the order it shows it.
#[derive(Debug, Default)]
pub struct Page {
    pub title: String,
    /// The white-noise tests frequencies were identified in (one column each).
    pub tests: Vec<String>,
    pub units: Vec<Unit>,
    pub cases: Vec<Case>,
    /// Every record of the `load` stages whose `status` tables the report read.
    pub records: Vec<RecordStatus>,
    pub stages: Vec<Provenance>,
    /// Kinds of results the report had no input for (said on the page, not an error).
    pub absent: Vec<String>,
}

#[derive(Debug, Default)]
pub struct Unit {
    pub name: String,
    /// Per test in `Page::tests`, the identified frequency.
    pub frequencies: Vec<Option<f64>>,
    /// Toppling detected in the records: (motion, impact time, confidence).
    pub topplings: Vec<(String, f64, f64)>,
    /// Whether the toppling detector looked at this unit at all.
    pub detected: bool,
    /// The report's own figure of the unit (relative link).
    pub figure: Option<String>,
    pub rocking: Vec<Rocking>,
    pub fragility: Vec<Fragility>,
    pub rolling: Vec<Rolling>,
}

/// One `simulate_toppling` stage's runs of a unit.
#[derive(Debug)]
pub struct Rocking {
    pub stage: String,
    pub runs: Vec<RockingRun>,
}

#[derive(Debug)]
pub struct RockingRun {
    pub motion: String,
    pub overturned: bool,
    pub overturn_time_s: Option<f64>,
    pub max_abs_theta_rad: f64,
    pub impacts: i64,
    pub figure: Option<String>,
}

/// One `toppling_fragility` stage's fit.
#[derive(Debug)]
pub struct Fragility {
    pub stage: String,
    pub im_measure: String,
    /// In the table's unit (m/s² for pfa, m/s for pfv).
    pub median: Option<f64>,
    pub beta: Option<f64>,
    pub runs: i64,
    pub overturned: i64,
    pub note: String,
    pub figure: Option<String>,
}

/// One `simulate_rolling` stage's runs of a unit.
#[derive(Debug)]
pub struct Rolling {
    pub stage: String,
    pub runs: Vec<RollingRun>,
}

#[derive(Debug)]
pub struct RollingRun {
    pub motion: String,
    pub peak_displacement_m: f64,
    pub peak_yaw_rad: f64,
    pub caster_flips: i64,
    pub breakaway_time_s: Option<f64>,
    pub figure: Option<String>,
}

/// One record's row of a `load` stage's `status` table.
#[derive(Debug)]
pub struct RecordStatus {
    pub stage: String,
    pub record: String,
    /// loaded, flagged, skipped or failed.
    pub status: String,
    pub file: String,
    pub reason: String,
}

/// One diagnosed case.
#[derive(Debug)]
pub struct Case {
    pub stage: String,
    pub case: String,
    pub mismatch: bool,
    pub verdict: String,
    pub window: Option<(f64, f64)>,
    pub rmse_before: f64,
    pub rmse_after: f64,
    pub explanation: String,
    pub figure: Option<String>,
}

/// What one stage whose results the report shows ran with.
#[derive(Debug)]
pub struct Provenance {
    pub stage: String,
    pub stage_type: String,
    pub version: String,
    /// The outputs of the stage the report read (`transfer_functions.identified`).
    pub read: Vec<String>,
    /// Normalised parameters, as JSON.
    pub params: String,
    /// Input name → content hash.
    pub inputs: Vec<(String, String)>,
    pub shakeflow_version: String,
}

/// `&`, `<`, `>`, `"` and `'` as character references: safe in text and in quoted attributes.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A relative URL from path segments as they are named on disk: every byte outside
/// `[A-Za-z0-9-._~=]` percent-encoded (a `%` of a Hive-encoded partition value becomes `%25`).
pub fn relative_url(segments: &[&str]) -> String {
    let mut out = String::new();
    for (i, segment) in segments.iter().enumerate() {
        if i > 0 {
            out.push('/');
        }
        for b in segment.bytes() {
            if b.is_ascii_alphanumeric() || b"-._~=".contains(&b) {
                out.push(b as char);
            } else {
                let _ = write!(out, "%{b:02X}");
            }
        }
    }
    out
}

/// An HTML id from a name: letters, digits, `-` and `_` kept, anything else `_`.
pub fn anchor(prefix: &str, name: &str) -> String {
    let body: String = name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
    format!("{prefix}-{body}")
}

fn num(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        "–".into()
    }
}

fn opt(v: Option<f64>, decimals: usize, unit: &str) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{} {unit}", num(v, decimals)).trim_end().to_string(),
        _ => "–".into(),
    }
}

const STYLE: &str = "body{font-family:DejaVu Sans,Helvetica,Arial,sans-serif;margin:0 auto;max-width:1250px;padding:0 1em 3em;color:#222}
h1{font-size:1.6em;margin-top:1em}h2{border-bottom:2px solid #1f77b4;padding-bottom:.2em;margin-top:2em}
h3{margin-top:1.4em;color:#333}table{border-collapse:collapse;margin:.5em 0 1em}
td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left;vertical-align:top}th{background:#f0f4f8}
td.n{text-align:right;font-variant-numeric:tabular-nums}tr.hit td{background:#fdecea}
figure{margin:.6em 0 1.2em}figure img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption{font-size:.9em;color:#555}nav a{margin-right:.8em}.note{color:#555;font-size:.92em}
details{margin:.4em 0 1em}summary{cursor:pointer;color:#1f77b4}pre{background:#f6f6f6;padding:.5em;overflow-x:auto;font-size:.85em;white-space:pre-wrap}
code{font-size:.9em}";

/// The page's bytes.
pub fn render(page: &Page) -> String {
    let mut h = String::new();
    let title = escape(&page.title);
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    h.push_str("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
    let _ = writeln!(h, "<title>{title}</title>\n<style>\n{STYLE}\n</style>\n</head>\n<body>");
    let _ = writeln!(h, "<h1>{title}</h1>");
    h.push_str("<nav><a href=\"#summary\">Summary</a>");
    for unit in &page.units {
        let _ = write!(h, "<a href=\"#{}\">{}</a>", anchor("unit", &unit.name), escape(&unit.name));
    }
    if !page.records.is_empty() {
        h.push_str("<a href=\"#records\">Records</a>");
    }
    if !page.cases.is_empty() {
        h.push_str("<a href=\"#diagnosis\">Diagnosis</a>");
    }
    h.push_str("<a href=\"#provenance\">Provenance</a></nav>\n");
    summary(&mut h, page);
    if !page.records.is_empty() {
        records(&mut h, &page.records);
    }
    for unit in &page.units {
        unit_section(&mut h, page, unit);
    }
    if !page.cases.is_empty() {
        diagnosis(&mut h, &page.cases);
    }
    provenance(&mut h, &page.stages);
    h.push_str("</body>\n</html>\n");
    h
}

fn summary(h: &mut String, page: &Page) {
    h.push_str("<section id=\"summary\">\n<h2>Summary</h2>\n");
    let toppled: usize = page.units.iter().map(|u| u.topplings.len()).sum();
    let toppled_units = page.units.iter().filter(|u| !u.topplings.is_empty()).count();
    let mut facts = vec![format!("{} units", page.units.len())];
    if !page.tests.is_empty() {
        facts.push(format!("frequencies from {} white-noise tests", page.tests.len()));
    }
    if page.units.iter().any(|u| u.detected) {
        facts.push(format!("{toppled} toppling events in the records ({toppled_units} units)"));
    }
    if !page.cases.is_empty() {
        let explained = page.cases.iter().filter(|c| c.mismatch && c.verdict != "unexplained").count();
        let mismatched = page.cases.iter().filter(|c| c.mismatch).count();
        facts.push(format!(
            "{} diagnosed cases, {mismatched} disagreeing with the model, {explained} explained",
            page.cases.len()
        ));
    }
    let _ = writeln!(h, "<p>{}.</p>", escape(&facts.join("; ")));
    if !page.absent.is_empty() {
        let _ = writeln!(
            h,
            "<p class=\"note\">Not in this study's report inputs: {}.</p>",
            escape(&page.absent.join(", "))
        );
    }
    h.push_str("<table>\n<tr><th>unit</th>");
    for test in &page.tests {
        let _ = write!(h, "<th>f {} [Hz]</th>", escape(test));
    }
    h.push_str("<th>toppled in the records</th><th>rocking model: overturned</th><th>fragility median, β</th><th>rolling: peak displacement</th></tr>\n");
    for unit in &page.units {
        let hit = if unit.topplings.is_empty() { "" } else { " class=\"hit\"" };
        let _ = write!(h, "<tr{hit}><td><a href=\"#{}\">{}</a></td>", anchor("unit", &unit.name), escape(&unit.name));
        for f in &unit.frequencies {
            let _ = write!(h, "<td class=\"n\">{}</td>", opt(*f, 2, ""));
        }
        let toppled = if !unit.detected {
            "–".to_string()
        } else if unit.topplings.is_empty() {
            "never".to_string()
        } else {
            unit.topplings.iter().map(|(m, t, _)| format!("{m} at {t:.2} s")).collect::<Vec<_>>().join(", ")
        };
        let _ = write!(h, "<td>{}</td>", escape(&toppled));
        let rocking: Vec<String> = unit
            .rocking
            .iter()
            .map(|r| format!("{} of {} motions", r.runs.iter().filter(|x| x.overturned).count(), r.runs.len()))
            .collect();
        let _ = write!(h, "<td>{}</td>", escape(&dash_if_empty(rocking)));
        let fragility: Vec<String> = unit.fragility.iter().map(fragility_short).collect();
        let _ = write!(h, "<td>{}</td>", escape(&dash_if_empty(fragility)));
        let rolling: Vec<String> = unit
            .rolling
            .iter()
            .map(|r| {
                let peak = r.runs.iter().map(|x| x.peak_displacement_m).fold(f64::NAN, f64::max);
                format!("{} m (largest of {} motions)", num(peak, 3), r.runs.len())
            })
            .collect();
        let _ = writeln!(h, "<td>{}</td></tr>", escape(&dash_if_empty(rolling)));
    }
    h.push_str("</table>\n</section>\n");
}

fn dash_if_empty(items: Vec<String>) -> String {
    if items.is_empty() {
        "–".into()
    } else {
        items.join("; ")
    }
}

/// `0.58 g, β 0.50` (pfa in g) or the fit's own note when there is no fit.
fn fragility_short(f: &Fragility) -> String {
    match (f.median, f.beta) {
        (Some(median), Some(beta)) if f.im_measure == "pfa" => {
            format!("{:.2} g, β {beta:.2}", median / crate::units::G0)
        }
        (Some(median), Some(beta)) => format!("{median:.3} m/s, β {beta:.2}"),
        _ => format!("no fit ({} of {} runs overturned)", f.overturned, f.runs),
    }
}

fn figure(h: &mut String, src: &str, caption: &str) {
    let caption = escape(caption);
    let _ = writeln!(
        h,
        "<figure><img src=\"{}\" alt=\"{caption}\"><figcaption>{caption}</figcaption></figure>",
        escape(src)
    );
}

fn unit_section(h: &mut String, page: &Page, unit: &Unit) {
    let name = escape(&unit.name);
    let _ = writeln!(
        h,
        "<section class=\"unit\" id=\"{}\" data-unit=\"{name}\">\n<h2>{name}</h2>",
        anchor("unit", &unit.name)
    );
    if !page.tests.is_empty() {
        h.push_str("<h3>Frequencies (transfer functions of the white-noise tests)</h3>\n<table><tr>");
        for test in &page.tests {
            let _ = write!(h, "<th>{}</th>", escape(test));
        }
        h.push_str("</tr><tr>");
        for f in &unit.frequencies {
            let _ = write!(h, "<td class=\"n\">{}</td>", opt(*f, 3, "Hz"));
        }
        h.push_str("</tr></table>\n");
    }
    if unit.detected {
        h.push_str("<h3>Toppling in the records</h3>\n");
        if unit.topplings.is_empty() {
            h.push_str("<p>No toppling detected in any motion.</p>\n");
        } else {
            h.push_str("<table><tr><th>motion</th><th>impact time [s]</th><th>confidence</th></tr>\n");
            for (motion, time, confidence) in &unit.topplings {
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                    escape(motion),
                    num(*time, 3),
                    num(*confidence, 2)
                );
            }
            h.push_str("</table>\n");
        }
    }
    if let Some(src) = &unit.figure {
        figure(h, src, &format!("{}: floor and top acceleration, transfer functions and coherence", unit.name));
    }
    for rocking in &unit.rocking {
        let overturned = rocking.runs.iter().filter(|r| r.overturned).count();
        let _ = writeln!(
            h,
            "<h3>Rocking simulations <span class=\"note\">(stage {})</span></h3>\n<p>Overturned in {overturned} of {} motions.</p>",
            escape(&rocking.stage),
            rocking.runs.len()
        );
        h.push_str(
            "<table><tr><th>motion</th><th>overturned</th><th>at [s]</th><th>max |θ| [rad]</th><th>impacts</th></tr>\n",
        );
        for r in &rocking.runs {
            let _ = writeln!(
                h,
                "<tr{}><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                if r.overturned { " class=\"hit\"" } else { "" },
                escape(&r.motion),
                if r.overturned { "yes" } else { "no" },
                opt(r.overturn_time_s, 2, ""),
                num(r.max_abs_theta_rad, 4),
                r.impacts
            );
        }
        h.push_str("</table>\n");
        figures_per_motion(h, &unit.name, rocking.runs.iter().map(|r| (&r.motion, &r.figure)));
    }
    for f in &unit.fragility {
        let _ = writeln!(
            h,
            "<h3>Fragility <span class=\"note\">(stage {})</span></h3>\n<p>{}: {} of {} runs overturned. {}</p>",
            escape(&f.stage),
            escape(&fragility_short(f)),
            f.overturned,
            f.runs,
            escape(&f.note)
        );
        if let Some(src) = &f.figure {
            figure(h, src, &format!("{}: probability of overturning", unit.name));
        }
    }
    for rolling in &unit.rolling {
        let _ =
            writeln!(h, "<h3>Rolling simulations <span class=\"note\">(stage {})</span></h3>", escape(&rolling.stage));
        h.push_str("<table><tr><th>motion</th><th>peak displacement [m]</th><th>peak yaw [°]</th><th>caster flips</th><th>starts rolling at [s]</th></tr>\n");
        for r in &rolling.runs {
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                escape(&r.motion),
                num(r.peak_displacement_m, 3),
                num(r.peak_yaw_rad.to_degrees(), 1),
                r.caster_flips,
                r.breakaway_time_s.map_or("never".into(), |t| num(t, 2))
            );
        }
        h.push_str("</table>\n");
        figures_per_motion(h, &unit.name, rolling.runs.iter().map(|r| (&r.motion, &r.figure)));
    }
    h.push_str("</section>\n");
}

/// Per-motion figures, folded away (the browser still loads them).
fn figures_per_motion<'a>(h: &mut String, unit: &str, figures: impl Iterator<Item = (&'a String, &'a Option<String>)>) {
    let figures: Vec<(&String, &String)> = figures.filter_map(|(m, f)| f.as_ref().map(|f| (m, f))).collect();
    if figures.is_empty() {
        return;
    }
    let _ = writeln!(h, "<details><summary>{} figures, one per motion</summary>", figures.len());
    for (motion, src) in figures {
        figure(h, src, &format!("{unit} under {motion}"));
    }
    h.push_str("</details>\n");
}

/// Every record with its status: counts, the records to look at (flagged, skipped, failed) with
/// their reasons, and the loaded ones folded away.
fn records(h: &mut String, records: &[RecordStatus]) {
    const ORDER: [&str; 4] = ["failed", "skipped", "flagged", "loaded"];
    h.push_str("<section id=\"records\">\n<h2>Records</h2>\n");
    let count = |status: &str| records.iter().filter(|r| r.status == status).count();
    let counts: Vec<String> = ORDER.iter().map(|s| format!("{} {s}", count(s))).collect();
    let _ = writeln!(
        h,
        "<p>{} record(s): {}. Flagged records loaded whole with something to know; skipped ones (<code>on_error: skip</code>) and failed ones have no table from this run.</p>",
        records.len(),
        counts.join(", ")
    );
    let row = |h: &mut String, r: &RecordStatus| {
        let _ = writeln!(
            h,
            "<tr{}><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            if r.status == "loaded" { "" } else { " class=\"hit\"" },
            escape(&r.record),
            escape(&r.status),
            escape(&r.stage),
            escape(&r.file),
            escape(&r.reason)
        );
    };
    const HEAD: &str = "<table><tr><th>record</th><th>status</th><th>stage</th><th>file</th><th>reason</th></tr>\n";
    let attention: Vec<&RecordStatus> =
        ORDER[..3].iter().flat_map(|s| records.iter().filter(move |r| r.status == *s)).collect();
    if !attention.is_empty() {
        h.push_str(HEAD);
        for r in attention {
            row(h, r);
        }
        h.push_str("</table>\n");
    }
    let loaded: Vec<&RecordStatus> = records.iter().filter(|r| r.status == "loaded").collect();
    if !loaded.is_empty() {
        let _ = writeln!(h, "<details><summary>{} loaded record(s)</summary>", loaded.len());
        h.push_str(HEAD);
        for r in loaded {
            row(h, r);
        }
        h.push_str("</table>\n</details>\n");
    }
    h.push_str("</section>\n");
}

fn diagnosis(h: &mut String, cases: &[Case]) {
    h.push_str("<section id=\"diagnosis\">\n<h2>Diagnosis</h2>\n");
    h.push_str("<p class=\"note\">Where the toppling model (the rolling cart, for units on casters) and each case's records disagree, which physics explains it, and the noise-normalised misfit before and after (1 is sensor noise).</p>\n");
    h.push_str(
        "<table><tr><th>case</th><th>verdict</th><th>window [s]</th><th>misfit before</th><th>after</th></tr>\n",
    );
    for c in cases {
        let _ = writeln!(
            h,
            "<tr{}><td><a href=\"#{}\">{}</a></td><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
            if c.mismatch { " class=\"hit\"" } else { "" },
            anchor("case", &c.case),
            escape(&c.case),
            escape(&c.verdict),
            c.window.map_or("–".into(), |(a, b)| format!("{a:.2} – {b:.2}")),
            num(c.rmse_before, 2),
            num(c.rmse_after, 2)
        );
    }
    h.push_str("</table>\n");
    for c in cases {
        let _ = writeln!(
            h,
            "<h3 id=\"{}\">{} <span class=\"note\">(stage {})</span></h3>\n<p><b>{}</b>: {}</p>",
            anchor("case", &c.case),
            escape(&c.case),
            escape(&c.stage),
            escape(&c.verdict),
            escape(&c.explanation)
        );
        if let Some(src) = &c.figure {
            figure(h, src, &format!("case {}: records, models and residuals", c.case));
        }
    }
    h.push_str("</section>\n");
}

fn provenance(h: &mut String, stages: &[Provenance]) {
    h.push_str("<section id=\"provenance\">\n<h2>Provenance</h2>\n");
    h.push_str("<p class=\"note\">Per stage whose results this page shows: its type and version, the parameters it ran with and the content hashes of what it read (as recorded in its artifacts; <code>shakeflow.lock</code> holds the same).</p>\n");
    h.push_str(
        "<table><tr><th>stage</th><th>type (version)</th><th>read here</th><th>parameters</th><th>inputs</th></tr>\n",
    );
    for s in stages {
        let inputs: Vec<String> = s
            .inputs
            .iter()
            .map(|(name, hash)| format!("{} {}", escape(name), escape(&hash.chars().take(12).collect::<String>())))
            .collect();
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{} ({}), shakeflow {}</td><td>{}</td><td><pre>{}</pre></td><td>{}</td></tr>",
            escape(&s.stage),
            escape(&s.stage_type),
            escape(&s.version),
            escape(&s.shakeflow_version),
            escape(&s.read.join(", ")),
            escape(&s.params),
            inputs.join("<br>")
        );
    }
    h.push_str("</table>\n</section>\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_from_data_cannot_open_a_tag_or_leave_an_attribute() {
        assert_eq!(
            escape("<script>a & \"b\" 'c'</script>"),
            "&lt;script&gt;a &amp; &quot;b&quot; &#39;c&#39;&lt;/script&gt;"
        );
        let page = Page {
            title: "study <b>".into(),
            units: vec![Unit { name: "U\"><script>x</script>".into(), detected: true, ..Unit::default() }],
            ..Page::default()
        };
        let html = render(&page);
        assert!(!html.contains("<script"), "{html}");
        assert!(!html.contains("<b>"));
        assert!(html.contains("U&quot;&gt;&lt;script&gt;x&lt;/script&gt;"));
        assert_eq!(html, render(&page), "the same page twice");
    }

    #[test]
    fn links_are_relative_and_percent_encoded_as_the_files_are_named() {
        assert_eq!(
            relative_url(&["..", "rocking", "figures", "motion=FB-4.png"]),
            "../rocking/figures/motion=FB-4.png"
        );
        // A Hive-encoded partition value on disk (`090%20%28CUE%29`) is reached through `%25`.
        assert_eq!(
            relative_url(&["figures", "motion=090%20%28CUE%29.png"]),
            "figures/motion=090%2520%2528CUE%2529.png"
        );
        assert_eq!(relative_url(&["a b", "é"]), "a%20b/%C3%A9");
        assert_eq!(anchor("unit", "PS 2/x"), "unit-PS_2_x");
    }
}
