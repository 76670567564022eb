//! The `llrp-gateway` command line ([`llrp_gateway::cli`]).

fn main() -> std::process::ExitCode {
    llrp_gateway::cli::main()
}
