//! Project automation tasks: `cargo run -p xtask -- <task> [args]`.

mod bench_bake;
mod demo;
mod scenes;

/// Exit status 0 on success, 2 for a task or argument it does not know (before any work), 1 when
/// the task fails: one `error:` line with its causes, never a backtrace.
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("scenes") => scenes::run(&args[1..]),
        Some("demo") => demo::run(&args[1..]),
        Some("eval") => demo::run_eval(&args[1..]),
        Some("bench-bake") => bench_bake::run(&args[1..]),
        _ => {
            eprintln!("usage: cargo run -p xtask -- <task>\n\ntasks:\n  demo [SCENE]                    bake a scene (default: the Cornell box) and render a frame headless into out/\n  eval [--quick|--full] [--out DIR]  accuracy against speed: bake a sweep of settings, measure cost and error, write CSV and charts\n  eval --budget                  the error budget of the default bake, one idealised stage at a time\n  eval --targets                 the accuracy targets, measured as ../shared/notes/metrics.md defines them\n  eval --emitters | --sky | --probes  emissive surfaces, the sky and a sun, or the probes, against the reference\n  scenes [--out DIR] [--check]   write (or verify) the test scenes in scenes/\n  bench-bake [--compare] [--only NAME]  time the bakes that have bake-time targets (--compare: also on --backend vulkan)");
            std::process::exit(2);
        }
    }
}
