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
    #[cfg(unix)]
    clean_up_on_signals();
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

/// Ended by Ctrl-C, SIGTERM or SIGHUP, a command's outputs being written
/// are temporary files beside their targets: a thread of its own waits for
/// those signals, removes the files, and lets the signal end the process
/// as it would have (so a shell's loop stops at Ctrl-C, and the exit status
/// names the signal). A signal the process was started to ignore (`nohup`,
/// a background job's SIGINT) stays ignored.
#[cfg(unix)]
fn clean_up_on_signals() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let ignored = |sig: i32| {
        // SAFETY: reads the current disposition only (no new action).
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            libc::sigaction(sig, std::ptr::null(), &mut old) == 0
                && old.sa_sigaction == libc::SIG_IGN
        }
    };
    let wanted: Vec<i32> = [SIGINT, SIGTERM, SIGHUP]
        .into_iter()
        .filter(|&s| !ignored(s))
        .collect();
    let Ok(mut signals) = signal_hook::iterator::Signals::new(&wanted) else {
        return;
    };
    std::thread::spawn(move || {
        if let Some(sig) = signals.forever().next() {
            snell::atomic::discard_and_close();
            // On its own line, after a progress bar's.
            use std::io::IsTerminal;
            let fresh_line = if std::io::stderr().is_terminal() {
                "\n"
            } else {
                ""
            };
            eprintln!("{fresh_line}interrupted");
            let _ = signal_hook::low_level::emulate_default_handler(sig);
            std::process::exit(128 + sig);
        }
    });
}
