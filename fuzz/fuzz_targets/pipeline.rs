//! The pipeline parser and planner: any text gives a plan or a UserError, never a panic or an
//! abort. The file is named inside a folder that does not exist, so parameters naming files
//! find none.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let path = std::path::Path::new("/nonexistent-shakeflow-fuzz/pipeline.yaml");
    if let Ok(file) = shakeflow::pipeline::spec::PipelineFile::parse(path, text.to_string()) {
        let _ = shakeflow::pipeline::plan::Plan::new(file);
    }
});
