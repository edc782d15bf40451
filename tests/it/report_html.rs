//! The study report (`report`'s `index.html`) as a browser shows it: rendered by headless
//! Chromium, every image must load (naturalWidth > 0) and every unit must have its section.
//! `check_in_chromium` is shared with the demo study test, which checks the full demo page.
//!
//! Chromium is Debian's `chromium` (`make test` installs it through tests/system/chromium.sh
//! when it runs as root with apt) or the binary `SHAKEFLOW_CHROMIUM` names. Without it these
//! tests fail, saying how to install it.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{self, shakeflow, state_yaml, stderr, stdout};

/// What the page showed in the browser.
pub struct Rendered {
    /// Every `<img>`: its `src` as written and its natural width once loaded (0: broken).
    pub images: Vec<(String, u64)>,
    /// The `data-unit` of every unit section, in page order.
    pub units: Vec<String>,
    /// Every `src` and `href` in the page's body (not the `<base>` the probe adds).
    pub links: Vec<String>,
}

fn chromium() -> PathBuf {
    if let Some(path) = std::env::var_os("SHAKEFLOW_CHROMIUM") {
        return PathBuf::from(path);
    }
    let found = std::env::var_os("PATH")
        .into_iter()
        .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .map(|dir| dir.join("chromium"))
        .find(|p| p.is_file());
    found.unwrap_or_else(|| {
        panic!(
            "the report test needs headless Chromium and none was found: run `make test` as root (it installs \
             Debian's chromium through tests/system/chromium.sh), or `sudo apt-get install chromium`, or set \
             SHAKEFLOW_CHROMIUM to a Chromium/Chrome binary"
        )
    })
}

/// A script appended to a copy of the page: after every image has loaded or failed (the load
/// event), it writes what it saw as JSON into the DOM that `--dump-dom` prints.
const PROBE: &str = "<script>window.addEventListener('load',()=>{const r={\
images:[...document.images].map(i=>[i.getAttribute('src'),i.naturalWidth]),\
units:[...document.querySelectorAll('section.unit')].map(s=>s.dataset.unit),\
links:[...document.querySelectorAll('body [src],body [href]')].map(e=>e.getAttribute('src')||e.getAttribute('href'))};\
const p=document.createElement('pre');p.id='shakeflow-probe';p.textContent=JSON.stringify(r);\
document.body.appendChild(p);});</script>";

/// Renders `index` in headless Chromium. The page itself is not touched: a copy with the probe
/// and a `<base>` pointing at the page's folder (so its relative links resolve as they do for
/// the original) is rendered from a temporary folder.
pub fn check_in_chromium(index: &Path) -> Rendered {
    let html = std::fs::read_to_string(index).unwrap();
    assert!(!html.contains("<script"), "the report page runs no scripts of its own");
    let folder = index.parent().unwrap().canonicalize().unwrap();
    let base = format!("<base href=\"file://{}/\">", folder.display());
    let probed =
        html.replacen("<head>", &format!("<head>{base}"), 1).replacen("</body>", &format!("{PROBE}</body>"), 1);
    let work = crate::tempdir::tempdir().unwrap();
    let probe = work.path().join("probe.html");
    std::fs::write(&probe, probed).unwrap();
    let out = Command::new(chromium())
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--allow-file-access-from-files"])
        .arg(format!("--user-data-dir={}", work.path().join("profile").display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", probe.display()))
        .output()
        .expect("chromium starts");
    let dom = String::from_utf8_lossy(&out.stdout);
    let json = dom
        .split_once("<pre id=\"shakeflow-probe\">")
        .and_then(|(_, rest)| rest.split_once("</pre>"))
        .map(|(json, _)| json.replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&"))
        .unwrap_or_else(|| {
            panic!("chromium printed no probe result; stderr:\n{}", String::from_utf8_lossy(&out.stderr))
        });
    let value: serde_json::Value = serde_json::from_str(&json).unwrap();
    let strings = |key: &str| -> Vec<String> {
        value[key].as_array().unwrap().iter().map(|v| v.as_str().unwrap_or_default().to_string()).collect()
    };
    let images = value["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| (i[0].as_str().unwrap().to_string(), i[1].as_u64().unwrap()))
        .collect();
    Rendered { images, units: strings("units"), links: strings("links") }
}

/// The checks every report page must pass: images load, links stay local, every unit shows.
pub fn assert_page_shows(index: &Path, units: &[&str], min_images: usize) -> Rendered {
    let page = check_in_chromium(index);
    let broken: Vec<&String> = page.images.iter().filter(|(_, w)| *w == 0).map(|(s, _)| s).collect();
    assert!(broken.is_empty(), "images that did not load: {broken:?}");
    assert!(page.images.len() >= min_images, "{} images, expected at least {min_images}", page.images.len());
    let absolute: Vec<&String> =
        page.links.iter().filter(|l| l.contains("://") || l.starts_with('/') || l.starts_with("data:")).collect();
    assert!(absolute.is_empty(), "links that leave the output folder: {absolute:?}");
    for unit in units {
        assert!(page.units.iter().any(|u| u == unit), "no section for unit {unit}; sections: {:?}", page.units);
    }
    assert_eq!(page.units.len(), units.len(), "sections: {:?}", page.units);
    page
}

const REPORT_STAGES: &str = r#"  rocking:
    type: simulate_toppling
    inputs: [baseline]
    params:
      preset: PS2
      horizontal: ax_mps2
  report:
    type: report
    inputs: [rocking.events]
    params:
      title: a small study <with> "quotes"
"#;

fn project_with_report() -> crate::tempdir::TempDir {
    let project = common::small_project();
    let pipeline = format!("{}{REPORT_STAGES}", common::PIPELINE);
    std::fs::write(project.path().join("pipeline.yaml"), pipeline).unwrap();
    project
}

#[test]
fn a_report_with_only_rocking_results_renders_with_every_figure() {
    let project = project_with_report();
    let out = shakeflow(&["run", "pipeline.yaml"], project.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let index = project.path().join("out/report/index.html");
    let html = std::fs::read_to_string(&index).unwrap();
    assert!(html.contains("<h1>a small study &lt;with&gt; &quot;quotes&quot;</h1>"), "{html}");
    assert!(html.contains("Not in this study's report inputs: frequencies"), "absent inputs are said");
    let page = assert_page_shows(&index, &["PS2"], 2);
    let srcs: Vec<&str> = page.images.iter().map(|(s, _)| s.as_str()).collect();
    assert_eq!(srcs, ["../rocking/figures/motion=FB-1.png", "../rocking/figures/motion=FB-2.png"]);

    // The page is an output like the others: in the lockfile, hashed, and a change is seen.
    let state = state_yaml(&project.path().join("out"));
    assert!(state["stages"]["report"]["units"]["*"]["files"]["index.html"].is_string(), "{state:?}");
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], project.path()));
    assert!(status.contains("report             up to date"), "{status}");
    std::fs::write(&index, html.replace("PS2", "PS3")).unwrap();
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], project.path()));
    assert!(status.contains("report             stale: output file `index.html` was modified on disk"), "{status}");
    let out = shakeflow(&["run", "pipeline.yaml"], project.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(std::fs::read_to_string(&index).unwrap(), html, "rerun: the same bytes");

    // Another folder, the same inputs: the same page, byte for byte.
    let other = project_with_report();
    assert!(shakeflow(&["run", "pipeline.yaml"], other.path()).status.success());
    assert_eq!(std::fs::read(other.path().join("out/report/index.html")).unwrap(), html.as_bytes());
}

#[test]
fn the_page_is_not_a_dataset_to_read() {
    let project = common::small_project();
    let pipeline =
        format!("{}{REPORT_STAGES}  again:\n    type: report\n    inputs: [report.index.html]\n", common::PIPELINE);
    std::fs::write(project.path().join("pipeline.yaml"), pipeline).unwrap();
    let out = shakeflow(&["validate", "pipeline.yaml"], project.path());
    assert!(!out.status.success());
    let text = stderr(&out);
    assert!(text.contains("`report.index.html` is a page for people, not a dataset"), "{text}");
    assert!(text.contains("pipeline.yaml:"), "names the line: {text}");
}
