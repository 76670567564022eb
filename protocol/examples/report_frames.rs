//! Writes the benchmark's RO_ACCESS_REPORT frames to a file, for the sllurp baseline.
//! Usage: report_frames OUT TAGS_PER_FRAME FRAMES

use std::io::Write;

fn main() -> std::io::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 4 {
        eprintln!("usage: report_frames OUT TAGS_PER_FRAME FRAMES");
        std::process::exit(2);
    }
    let n: usize = args[2].parse().expect("TAGS_PER_FRAME is a number");
    let frames: usize = args[3].parse().expect("FRAMES is a number");
    let frame = llrp::sample::benchmark_report(n, 7).to_bytes();
    let mut out = std::io::BufWriter::new(std::fs::File::create(&args[1])?);
    for _ in 0..frames {
        out.write_all(&frame)?;
    }
    out.flush()
}
