//! Records the commit the binary is built from (`SNELL_GIT`), so benchmark
//! tables name the code that measured them, not whichever repository the
//! command happens to run in.

use std::path::Path;
use std::process::Command;

fn git(args: &[&str]) -> Option<std::process::Output> {
    Command::new("git")
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stderr(std::process::Stdio::null())
        .output()
        .ok()
}

fn text(out: &std::process::Output) -> Option<String> {
    let s = String::from_utf8(out.stdout.clone())
        .ok()?
        .trim()
        .to_string();
    (out.status.success() && !s.is_empty()).then_some(s)
}

fn main() {
    // A commit moves HEAD's branch and the index; code changes touch these.
    for path in ["src", "benches", "Cargo.toml", "Cargo.lock", "build.rs"] {
        println!("cargo:rerun-if-changed={path}");
    }
    let describe = git(&["describe", "--always"]).and_then(|o| text(&o));
    if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]).and_then(|o| text(&o)) {
        let dir = Path::new(&dir);
        println!("cargo:rerun-if-changed={}", dir.join("HEAD").display());
        println!("cargo:rerun-if-changed={}", dir.join("index").display());
        println!(
            "cargo:rerun-if-changed={}",
            dir.join("packed-refs").display()
        );
        if let Some(head) = git(&["symbolic-ref", "-q", "HEAD"]).and_then(|o| text(&o)) {
            println!("cargo:rerun-if-changed={}", dir.join(head).display());
        }
    }
    let value = describe.map_or(String::new(), |s| {
        // Markdown left out: `bench --update` rewrites BENCHMARKS.md, which
        // is not a change of the code measured.
        let changed = git(&["diff", "--quiet", "HEAD", "--", ":/", ":(top,exclude)*.md"])
            .is_some_and(|o| o.status.code() == Some(1));
        if changed { s + "-dirty" } else { s }
    });
    println!("cargo:rustc-env=SNELL_GIT={value}");
}
