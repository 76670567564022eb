//! The `llrp-gateway` command line.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use llrp_gateway::decode::{decode_stream, DecodeOptions};

#[derive(Parser)]
#[command(
    name = "llrp-gateway",
    version,
    about = "Simulated LLRP reader, LLRP gateway and tag localizer"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Decode LLRP frames and print one JSON object per message.
    Decode {
        /// Input file with LLRP frames; `-` or nothing reads standard input.
        file: Option<PathBuf>,
        /// The input is hex text (whitespace allowed) instead of raw bytes.
        #[arg(long)]
        hex: bool,
        /// Re-encode each message and fail if the bytes differ from the input.
        #[arg(long)]
        roundtrip: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Decode {
            file,
            hex,
            roundtrip,
        } => {
            let mut input = Vec::new();
            let read = match file.as_deref() {
                None => std::io::stdin().read_to_end(&mut input),
                Some(p) if p.as_os_str() == "-" => std::io::stdin().read_to_end(&mut input),
                Some(p) => std::fs::File::open(p).and_then(|mut f| f.read_to_end(&mut input)),
            };
            if let Err(e) = read {
                eprintln!("llrp-gateway decode: cannot read input: {e}");
                return ExitCode::FAILURE;
            }
            let stdout = std::io::stdout();
            let mut out = std::io::BufWriter::new(stdout.lock());
            let result = decode_stream(&input, DecodeOptions { hex, roundtrip }, &mut out);
            let flushed = out.flush();
            match (result, flushed) {
                (Ok(_), Ok(())) => ExitCode::SUCCESS,
                (Err(e), _) => {
                    eprintln!("llrp-gateway decode: {e}");
                    ExitCode::FAILURE
                }
                (_, Err(e)) => {
                    eprintln!("llrp-gateway decode: writing output: {e}");
                    ExitCode::FAILURE
                }
            }
        }
    }
}
