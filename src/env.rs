//! The `SNELL_*` environment variables, read alike: unset or empty (a
//! script's `SNELL_ISA=` with nothing after it) is no setting at all, as
//! most tools take an empty variable; any other value is the reader's to
//! check, and a bad one is ignored with a warning.

/// The value of `name`, or `None` when it is unset, empty or not UTF-8
/// (no `SNELL_*` value is anything but ASCII).
pub fn setting(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.trim().is_empty())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_is_unset() {
        // A name no other test reads: tests run in threads of one process.
        let name = "SNELL_ENV_TEST_EMPTY_IS_UNSET";
        // SAFETY: no other thread reads or writes this variable.
        unsafe { std::env::set_var(name, " ") };
        assert_eq!(setting(name), None);
        unsafe { std::env::set_var(name, "avx2") };
        assert_eq!(setting(name).as_deref(), Some("avx2"));
        unsafe { std::env::remove_var(name) };
        assert_eq!(setting(name), None);
    }
}
