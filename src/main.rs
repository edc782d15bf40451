use std::process::ExitCode;

fn main() -> ExitCode {
    keep_freed_memory();
    match shakeflow::cli::main() {
        Ok(code) => code,
        Err(error) => {
            eprintln!("error: {error}");
            for cause in error.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::FAILURE
        }
    }
}

/// Records allocate and free buffers of megabytes. glibc serves each from fresh mmapped pages and
/// returns them on free, so every record page-faults and zeroes its memory again; keeping freed
/// memory in the heap lets the next record reuse it.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only tunes the allocator; called before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 64 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 128 << 20);
    }
}
