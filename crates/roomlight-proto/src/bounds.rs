//! What bounds a peer at the boundary, before anything it chose is read, logged or allocated:
//! the room token compared in constant time (whatever its length), a projector id checked
//! before it enters a log or a registry, peer strings escaped and cut for logs, and the largest
//! gRPC message each side decodes, derived from the room's dimensions.
//!
//! It knows nothing of agents or streams: callers pass the sizes they know.

/// Longest room token accepted, in bytes (config and Hello): the comparison always runs over
/// this many bytes, so its time does not depend on where the tokens differ or on their length.
pub const MAX_TOKEN_BYTES: usize = 1024;

/// Longest projector id, in bytes.
pub const MAX_PROJECTOR_ID: usize = 128;

/// Longest peer-chosen string a log line carries (escaped), in characters.
pub const MAX_LOGGED_CHARS: usize = 64;

/// A room token held by a process: its `Debug` prints `<secret>`, so printing a config (e.g.
/// `roomlight node --check`) never shows it.
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(pub String);

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<secret>")
    }
}

/// Whether `given` is `expected`, in time independent of both contents and of `given`'s length
/// (up to [`MAX_TOKEN_BYTES`]; a longer one is wrong anyway, since no config token is longer).
/// An empty `expected` matches nothing (configs refuse it; this is the second line).
pub fn token_matches(given: &str, expected: &str) -> bool {
    if expected.is_empty() || expected.len() > MAX_TOKEN_BYTES || given.len() > MAX_TOKEN_BYTES {
        return false;
    }
    let padded = |s: &str| {
        let mut buf = [0u8; MAX_TOKEN_BYTES];
        buf[..s.len()].copy_from_slice(s.as_bytes());
        buf
    };
    let (a, b) = (padded(given), padded(expected));
    // Every byte is compared whatever came before (no early exit), and the lengths too:
    // padding alone would let "t" match "t\0".
    let mut diff = (given.len() ^ expected.len()) as u64;
    for (x, y) in a.iter().zip(b.iter()) {
        diff |= u64::from(x ^ y);
    }
    std::hint::black_box(diff) == 0
}

/// Checks a projector id from a Hello: 1 to [`MAX_PROJECTOR_ID`] bytes, no control characters
/// (it names log lines, state and the registry). The reason, when refused.
pub fn check_projector_id(id: &str) -> Result<(), String> {
    if id.is_empty() || id.len() > MAX_PROJECTOR_ID {
        return Err(format!(
            "projector id of {} bytes: expected 1 to {MAX_PROJECTOR_ID}",
            id.len()
        ));
    }
    if id.chars().any(char::is_control) {
        return Err(format!(
            "projector id {}: expected no control characters",
            escaped(id)
        ));
    }
    Ok(())
}

/// A peer-chosen string as a log line may carry it: at most [`MAX_LOGGED_CHARS`] characters,
/// every control character and quote escaped (`escape_debug`), quoted, `…` when cut.
pub fn escaped(s: &str) -> String {
    let mut out = String::from("\"");
    let mut chars = s.chars();
    for c in chars.by_ref().take(MAX_LOGGED_CHARS) {
        out.extend(c.escape_debug());
    }
    if chars.next().is_some() {
        out.push('…');
    }
    out.push('"');
    out
}

/// At most `max` bytes of `s`, cut at a character boundary.
pub fn cut(s: &str, max: usize) -> &str {
    let mut end = s.len().min(max);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}

/// Bytes a node agent's message may take at most, for the camera agent to decode: its Hello
/// carries the attenuation its nodes remember, so the bound is the room's, `nonzeros` entries
/// of 28 bytes (a patch id and three doubles) and 64 bytes per node, with 1 MiB of headroom;
/// at least 4 MiB, at most 256 MiB.
pub fn node_message_limit(nodes: usize, nonzeros: usize) -> usize {
    let room = nonzeros
        .saturating_mul(28)
        .saturating_add(nodes.saturating_mul(64));
    room.saturating_add(1 << 20).clamp(4 << 20, 256 << 20)
}

/// Bytes a camera agent's message may take at most, for a node agent of this `resolution` to
/// decode (`None`: a display that draws no pixels): an Assign of its weights is 8 bytes per
/// pixel (a pixel index and a weight); an Attenuation is 56 bytes per patch of its node's
/// support (`p` and `s`). At least 32 MiB (a support of ~600 000 patches), at most 256 MiB.
pub fn room_message_limit(resolution: Option<(u32, u32)>) -> usize {
    let pixels = resolution.map_or(0, |(w, h)| (w as usize).saturating_mul(h as usize));
    pixels
        .saturating_mul(8)
        .saturating_add(1 << 20)
        .clamp(32 << 20, 256 << 20)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_match_only_when_equal_and_never_when_empty_or_too_long() {
        assert!(token_matches("s3cret", "s3cret"));
        assert!(!token_matches("s3cre", "s3cret"));
        assert!(
            !token_matches("s3cret\0", "s3cret"),
            "padding is not the token"
        );
        assert!(!token_matches("s3cret", "s3cret\0"));
        assert!(!token_matches("", ""), "the empty token matches nothing");
        let long = "x".repeat(MAX_TOKEN_BYTES + 1);
        assert!(!token_matches(&long, &long));
        let max = "y".repeat(MAX_TOKEN_BYTES);
        assert!(token_matches(&max, &max));
    }

    #[test]
    fn projector_ids_are_bounded_and_printable() {
        assert!(check_projector_id("p0").is_ok());
        assert!(check_projector_id("").is_err());
        assert!(check_projector_id(&"p".repeat(MAX_PROJECTOR_ID + 1)).is_err());
        let e = check_projector_id("p0\n2026 INFO forged").expect_err("newline");
        assert!(e.contains("\\n") && !e.contains('\n'), "{e}");
    }

    #[test]
    fn logged_strings_are_escaped_and_cut() {
        assert_eq!(escaped("p0"), "\"p0\"");
        assert_eq!(escaped("a\nb\u{1b}[31m\""), "\"a\\nb\\u{1b}[31m\\\"\"");
        let cut = escaped(&"z".repeat(1000));
        assert_eq!(cut.chars().count(), MAX_LOGGED_CHARS + 3);
        assert!(cut.ends_with("…\""));
    }

    #[test]
    fn message_limits_follow_the_room() {
        assert_eq!(node_message_limit(0, 0), 4 << 20);
        assert_eq!(
            node_message_limit(10_000, 1_000_000),
            28_000_000 + 640_000 + (1 << 20)
        );
        assert_eq!(node_message_limit(usize::MAX, usize::MAX), 256 << 20);
        assert_eq!(room_message_limit(None), 32 << 20);
        // A 4K projector's weights fit: 8.3 M pixels of 8 bytes.
        assert_eq!(
            room_message_limit(Some((3840, 2160))),
            3840 * 2160 * 8 + (1 << 20)
        );
        assert_eq!(room_message_limit(Some((u32::MAX, u32::MAX))), 256 << 20);
    }
}
