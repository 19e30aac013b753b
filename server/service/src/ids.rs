//! Random identifiers and secrets.

/// `bytes` random bytes as lowercase hex.
pub fn random_hex(bytes: usize) -> String {
    let mut buf = vec![0u8; bytes];
    if let Err(e) = getrandom::fill(&mut buf) {
        // The OS random source failing is not something a request can cause; without it no
        // id or ticket would be safe to hand out.
        panic!("the operating system's random source failed: {e}");
    }
    buf.iter().map(|b| format!("{b:02x}")).collect()
}

/// A new id such as `se_3f9a2b1c4d5e6f70` (prefix, underscore, 64 random bits).
pub fn new_id(prefix: &str) -> String {
    format!("{prefix}_{}", random_hex(8))
}

/// Compares secrets in time independent of where they differ.
pub fn constant_time_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_distinct_and_prefixed() {
        let a = new_id("se");
        let b = new_id("se");
        assert!(a.starts_with("se_") && a.len() == 19, "{a}");
        assert_ne!(a, b);
    }

    #[test]
    fn secrets_compare_by_content() {
        assert!(constant_time_eq("abcdef", "abcdef"));
        assert!(!constant_time_eq("abcdef", "abcdeg"));
        assert!(!constant_time_eq("abc", "abcd"));
    }
}
