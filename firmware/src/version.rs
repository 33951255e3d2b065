//! What the firmware is: its version and the commit it was built from, reported in the
//! status heartbeat (pages 11 and 12) and by the service channel's identify.

/// The firmware's version (major, minor, patch), from the crate's.
pub const VERSION: [u8; 3] = {
    const fn number(s: &str) -> u8 {
        let b = s.as_bytes();
        let mut v = 0u8;
        let mut i = 0;
        while i < b.len() {
            v = v * 10 + (b[i] - b'0');
            i += 1;
        }
        v
    }
    [
        number(env!("CARGO_PKG_VERSION_MAJOR")),
        number(env!("CARGO_PKG_VERSION_MINOR")),
        number(env!("CARGO_PKG_VERSION_PATCH")),
    ]
};

mod hash {
    include!(concat!(env!("OUT_DIR"), "/build_hash.rs"));
}

pub use hash::BUILD_HASH;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_version_is_the_crates_and_the_build_the_commits() {
        let v = env!("CARGO_PKG_VERSION");
        assert_eq!(format!("{}.{}.{}", VERSION[0], VERSION[1], VERSION[2]), v);
        // Built in a git checkout (as the tests are): HEAD's first 32 bits.
        if let Ok(out) = std::process::Command::new("git")
            .args(["rev-parse", "HEAD"])
            .output()
            && out.status.success()
            && std::env::var("FINGERTIP_BUILD_HASH").is_err()
        {
            let head = String::from_utf8_lossy(&out.stdout);
            assert_eq!(format!("{BUILD_HASH:08x}"), head[..8]);
        }
    }
}
