//! `snell`: the command line, a thin layer over the library.
//!
//! Every failure prints one `error: ...` line and exits with code 2 (bad input
//! or unusable output path); clap's usage errors exit 2 as well.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // A closed pipe downstream (`snell info v.nrrd | head -1`) ends the
    // process quietly, as it does other command-line tools, instead of
    // `println!` panicking on the failed write. Outputs are renamed into
    // place only when complete, so none is left half-written under its name.
    #[cfg(unix)]
    // SAFETY: restoring a signal's default disposition at start-up, before
    // any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Ended by Ctrl-C, SIGTERM or SIGHUP: the outputs being written are
    // temporary files beside their targets; remove them, so an interrupted
    // command leaves no debris, and exit as a shell expects of an
    // interrupted command. (The handler runs on a thread of its own.)
    let _ = ctrlc::set_handler(|| {
        snell::atomic::discard_and_close();
        eprintln!("interrupted");
        std::process::exit(130);
    });
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let mut msg = e.to_string();
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !msg.contains(&c) {
                    msg.push_str(": ");
                    msg.push_str(&c);
                }
            }
            eprintln!("error: {}", msg.replace('\n', " "));
            ExitCode::from(2)
        }
    }
}
