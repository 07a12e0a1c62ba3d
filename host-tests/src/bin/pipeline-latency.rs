//! Prints the bridge's added latency per pairing and timing mode, measured on the
//! host pipeline (`host_tests::pipeline::latency`; simulated time, so the figures
//! are exact and reproducible). `cargo xtask test` runs it.

use std::process::ExitCode;

use host_tests::pipeline::latency;

fn main() -> ExitCode {
    match latency::table(10, 40) {
        Ok(rows) => {
            println!("added latency, last input bit (sampled) -> first output bit, us:");
            println!("| pairing, timing | min | mean | max | frames |");
            println!("|---|---|---|---|---|");
            for (name, l) in rows {
                println!(
                    "| {name} | {:.2} | {:.2} | {:.2} | {} |",
                    l.min_ns / 1000.0,
                    l.mean_ns / 1000.0,
                    l.max_ns / 1000.0,
                    l.frames
                );
            }
            println!();
            println!(
                "firmware batch loop, added on top (end of input frame -> its output slot), us:"
            );
            println!("| input -> head, timing | min | mean | max | frames |");
            println!("|---|---|---|---|---|");
            for (name, l) in [
                ("XY2-100 -> XY2-100", latency::BatchLoop::XY2_TO_XY2),
                (
                    "XY3-100 24-bit -> XY3-100 24-bit",
                    latency::BatchLoop::XY3_TO_XY3,
                ),
            ] {
                for (mode, slaved) in [("free-running", false), ("slaved", true)] {
                    let m = l.measure(slaved, 10, 4_000);
                    println!(
                        "| {name}, {mode} | {:.1} | {:.1} | {:.1} | {} |",
                        m.min_ns / 1000.0,
                        m.mean_ns / 1000.0,
                        m.max_ns / 1000.0,
                        m.frames
                    );
                }
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("pipeline-latency: {e}");
            ExitCode::FAILURE
        }
    }
}
