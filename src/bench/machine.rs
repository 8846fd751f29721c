//! Where and when the numbers were measured, and how much memory they took.
//!
//! Everything here reads Linux `/proc` and degrades to `None` elsewhere: a
//! benchmark on another system still runs, it just reports less.

use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use super::results::Machine;

const KIB_PER_MIB: f64 = 1024.0;

/// The machine this process runs on.
pub fn machine() -> Machine {
    Machine {
        nproc: std::thread::available_parallelism().map_or(1, |n| n.get()),
        cpu_model: cpu_model(),
        mem_total_mib: proc_field("/proc/meminfo", "MemTotal").map(|k| k as f64 / KIB_PER_MIB),
        os: std::env::consts::OS.into(),
        arch: std::env::consts::ARCH.into(),
        snell_version: env!("CARGO_PKG_VERSION").into(),
        build_profile: if cfg!(debug_assertions) {
            "debug".into()
        } else {
            "release".into()
        },
        git: git_describe(),
    }
}

/// The CPU's model name with its family, model and clock, from
/// `/proc/cpuinfo` (see [`describe_cpu`]).
pub fn cpu_model() -> Option<String> {
    describe_cpu(&std::fs::read_to_string("/proc/cpuinfo").ok()?)
}

/// The CPU family number of `/proc/cpuinfo` (AMD Zen 4: 25, Zen 5: 26).
pub fn cpu_family() -> Option<u32> {
    family_of(&std::fs::read_to_string("/proc/cpuinfo").ok()?)
}

fn family_of(cpuinfo: &str) -> Option<u32> {
    first_processor_field(cpuinfo, "cpu family")?.parse().ok()
}

/// The non-empty value of `key` in the first processor's block of
/// `/proc/cpuinfo` text (the others repeat it).
fn first_processor_field<'a>(cpuinfo: &'a str, key: &str) -> Option<&'a str> {
    cpuinfo.split("\n\n").next()?.lines().find_map(|l| {
        let (k, v) = l.split_once(':')?;
        (k.trim() == key)
            .then(|| v.trim())
            .filter(|v| !v.is_empty())
    })
}

/// The first processor's `model name`, followed by its `cpu family`,
/// `model` and `cpu MHz` where present: virtual machines often report a
/// bare name ("AMD EPYC") for hosts of different generations and clocks
/// that ran the same code 1.5× apart (BENCHMARKS.md, *The same code on a
/// Zen 4 host*), so a recorded time names the numbers that tell them apart.
fn describe_cpu(cpuinfo: &str) -> Option<String> {
    let field = |key: &str| first_processor_field(cpuinfo, key);
    let name = field("model name")?;
    let mut details = Vec::new();
    if let Some(f) = field("cpu family") {
        details.push(format!("family {f}"));
    }
    if let Some(m) = field("model") {
        details.push(format!("model {m}"));
    }
    if let Some(mhz) = field("cpu MHz").and_then(|v| v.parse::<f64>().ok()) {
        details.push(format!("{mhz:.0} MHz"));
    }
    Some(if details.is_empty() {
        name.to_string()
    } else {
        format!("{name} ({})", details.join(", "))
    })
}

/// The commit the binary was built from (`build.rs`), so a table can be
/// traced to its code: with `-dirty` when a tracked file other than
/// Markdown differed from it at the build (documentation is left out
/// because `--update` itself rewrites BENCHMARKS.md). `None` for a build
/// outside a git checkout.
fn git_describe() -> Option<String> {
    Some(env!("SNELL_GIT"))
        .filter(|s| !s.is_empty())
        .map(String::from)
}

/// A `Key:   123 kB` field of a `/proc` status-like file, in KiB.
fn proc_field(path: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(Path::new(path)).ok()?;
    parse_kib_field(&text, key)
}

fn parse_kib_field(text: &str, key: &str) -> Option<u64> {
    text.lines().find_map(|l| {
        let (k, v) = l.split_once(':')?;
        if k.trim() != key {
            return None;
        }
        v.split_whitespace().next()?.parse().ok()
    })
}

/// Resets the process's peak resident set to its current size (Linux ≥ 4.0),
/// so the next [`peak_rss_mib`] is the peak since now. Returns false where
/// that is not possible; the peak is then the process's peak so far.
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Peak resident set (VmHWM) in MiB.
pub fn peak_rss_mib() -> Option<f64> {
    proc_field("/proc/self/status", "VmHWM").map(|k| k as f64 / KIB_PER_MIB)
}

/// Current resident set (VmRSS) in MiB.
pub fn rss_mib() -> Option<f64> {
    proc_field("/proc/self/status", "VmRSS").map(|k| k as f64 / KIB_PER_MIB)
}

/// CPU time counters: the whole machine's and this process's, in clock ticks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CpuSnapshot {
    busy: u64,
    total: u64,
    own: u64,
}

/// The machine's and this process's CPU time so far, waited-for child
/// processes included (Linux).
pub fn cpu_snapshot() -> Option<CpuSnapshot> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let own = std::fs::read_to_string("/proc/self/stat").ok()?;
    parse_cpu_snapshot(&stat, &own)
}

fn parse_cpu_snapshot(stat: &str, own: &str) -> Option<CpuSnapshot> {
    let cpu: Vec<u64> = stat
        .lines()
        .find(|l| l.starts_with("cpu "))?
        .split_whitespace()
        .skip(1)
        .map(|v| v.parse().ok())
        .collect::<Option<_>>()?;
    // user nice system idle iowait irq softirq steal [guest guest_nice]:
    // guest time is already inside user, so it is not added again.
    let total: u64 = cpu.iter().take(8).sum();
    let idle = cpu.get(3)? + cpu.get(4).copied().unwrap_or(0);
    // The command name may hold spaces and parentheses: fields start after the last ')'.
    let rest: Vec<&str> = own.rsplit_once(')')?.1.split_whitespace().collect();
    let utime: u64 = rest.get(11)?.parse().ok()?;
    let stime: u64 = rest.get(12)?.parse().ok()?;
    // Children this process waited for (POV-Ray and snell runs of `bench
    // --peer`) are this run's work too, not other processes'.
    let child = |i: usize| rest.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    Some(CpuSnapshot {
        busy: total - idle,
        total,
        own: utime + stime + child(13) + child(14),
    })
}

/// Share of the machine's CPU time between two snapshots that went to other
/// processes: anything well above zero means the timings are inflated.
pub fn other_cpu_share(before: &CpuSnapshot, after: &CpuSnapshot) -> Option<f64> {
    let total = after.total.checked_sub(before.total)?;
    let busy = after.busy.checked_sub(before.busy)?;
    let own = after.own.checked_sub(before.own)?;
    (total > 0).then(|| busy.saturating_sub(own) as f64 / total as f64)
}

/// Now as `YYYY-MM-DDTHH:MM:SSZ` (UTC).
pub fn utc_now() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    utc_timestamp(secs)
}

/// Seconds since the Unix epoch as an ISO 8601 UTC timestamp.
pub fn utc_timestamp(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// Proleptic Gregorian date of a day count since 1970-01-01 (H. Hinnant's
/// `civil_from_days`), to avoid a date-time dependency for one timestamp.
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps() {
        assert_eq!(utc_timestamp(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_timestamp(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_timestamp(1_700_000_000), "2023-11-14T22:13:20Z");
        assert_eq!(utc_timestamp(4_107_542_399), "2100-02-28T23:59:59Z");
    }

    #[test]
    fn cpu_descriptions() {
        let two = "processor\t: 0\nvendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\n\
                   model name\t: AMD EPYC\nstepping\t: 1\ncpu MHz\t\t: 2596.138\n\n\
                   processor\t: 1\ncpu family\t: 26\nmodel\t\t: 2\nmodel name\t: Other\n";
        assert_eq!(
            describe_cpu(two).as_deref(),
            Some("AMD EPYC (family 25, model 17, 2596 MHz)")
        );
        // A bare name stays bare; no name, no description.
        assert_eq!(
            describe_cpu("model name\t: Some CPU\n").as_deref(),
            Some("Some CPU")
        );
        assert_eq!(describe_cpu("cpu family\t: 6\nmodel\t: 85\n"), None);
        assert_eq!(describe_cpu(""), None);
        // The first processor's family; none without the field.
        assert_eq!(family_of(two), Some(25));
        assert_eq!(family_of("model name\t: Some CPU\n"), None);
    }

    #[test]
    fn proc_fields() {
        let status = "Name:\tsnell\nVmHWM:\t  123456 kB\nVmRSS:\t    1024 kB\n";
        assert_eq!(parse_kib_field(status, "VmHWM"), Some(123_456));
        assert_eq!(parse_kib_field(status, "VmRSS"), Some(1024));
        assert_eq!(parse_kib_field(status, "VmSwap"), None);
    }

    #[test]
    fn other_processes_share() {
        let stat =
            |user: u64, idle: u64| format!("cpu  {user} 0 0 {idle} 0 0 0 0 0 0\ncpu0 1 2 3\n");
        let own = |t: u64| format!("42 (snell (bench) x) R 1 1 1 0 -1 0 0 0 0 0 {t} 0 0 0 20");
        let a = parse_cpu_snapshot(&stat(100, 900), &own(50)).unwrap();
        // 200 ticks pass: 150 busy, of which 100 are ours.
        let b = parse_cpu_snapshot(&stat(250, 950), &own(150)).unwrap();
        assert_eq!(other_cpu_share(&a, &b), Some(0.25));
        assert_eq!(other_cpu_share(&b, &a), None);
        assert!(parse_cpu_snapshot("garbage", &own(1)).is_none());
    }

    #[test]
    fn memory_is_readable_on_linux() {
        if cfg!(target_os = "linux") {
            // The kernel updates VmHWM lazily, so it is not compared with VmRSS.
            assert!(peak_rss_mib().is_some_and(|m| m > 0.0));
            assert!(rss_mib().is_some_and(|m| m > 0.0));
        }
    }
}
