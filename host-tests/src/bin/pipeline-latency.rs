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
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("pipeline-latency: {e}");
            ExitCode::FAILURE
        }
    }
}
