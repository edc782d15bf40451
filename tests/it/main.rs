//! Every integration test in one binary: one link instead of one per file (a fresh clone
//! linked 24 test binaries). Each file is a module named for what it checks.

mod common;
// The library's std-only temporary folders (no `tempfile` dev-dependency: src/tempdir.rs says why).
mod rolling_common;
#[path = "../../src/tempdir.rs"]
mod tempdir;
mod toppling_common;

mod bad_input;
mod baseline_reference;
mod command_stages;
mod converged_defaults;
mod cpt_calibration;
mod cpt_occlusion;
mod cpt_project_inputs;
mod cpt_tracking;
mod cpt_video;
mod crash_safety;
mod demo_archive;
mod demo_study;
mod diagnose_cases;
mod example_pipelines;
mod export;
mod fragility_scipy;
mod hash_memo;
mod hostile_input;
mod intermediates;
mod interop;
mod load_shared_records;
mod mutation_harness;
mod nees_archive;
mod never_lose_data;
mod pipeline_runs;
mod record_components;
mod record_formats;
mod report_html;
mod rocking_demo_cases;
mod rocking_isolated;
mod rocking_published;
mod rocking_pulses;
mod rolling_diagnosis;
mod rolling_findings;
mod rolling_peers;
mod rolling_stage;
mod rolling_swivel;
mod sdof_identification;
mod slurm_client;
mod slurm_executor;
mod slurm_nodes;
mod stage_examples;
mod tidy;
mod toppling_demo_archive;
mod toppling_demo_cases;
mod toppling_robustness;
mod toppling_stages;
mod validate_all;
mod welch_scipy;
mod wheel;
mod work_units;
