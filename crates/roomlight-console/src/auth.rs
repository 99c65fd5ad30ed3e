//! Who may use the console: the token (compared in constant time) logs a browser in with an
//! `HttpOnly`, `SameSite=Strict` session cookie, or authorises an API client as
//! `Authorization: Bearer TOKEN`. A state-changing request made with the cookie must carry the
//! session's CSRF token in `X-Roomlight-CSRF` (a bearer token cannot be sent by a browser on its
//! own, so it needs none). Sessions are random 128-bit ids, at most [`MAX_SESSIONS`] (the
//! oldest goes), each for [`SESSION_LIFETIME`].

use axum::http::{HeaderMap, Method, header};
use rand::RngCore;
use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};
use subtle::ConstantTimeEq;

/// The session cookie's name.
pub const COOKIE: &str = "roomlight_session";
/// The CSRF header's name.
pub const CSRF_HEADER: &str = "x-roomlight-csrf";
/// At most this many sessions are kept; a new login past it ends the oldest.
pub const MAX_SESSIONS: usize = 64;
/// A session ends this long after its login.
pub const SESSION_LIFETIME: Duration = Duration::from_secs(12 * 3600);

/// One logged-in browser.
#[derive(Debug, Clone)]
struct Session {
    csrf: String,
    since: Instant,
}

/// The logged-in browsers.
#[derive(Debug, Default)]
pub struct Sessions {
    sessions: Mutex<HashMap<String, Session>>,
}

/// How a request was authorised.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Who {
    /// `Authorization: Bearer` with the token.
    Bearer,
    /// The session cookie; its CSRF token.
    Session { csrf: String },
}

/// Why a request was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Denied {
    /// No valid token or session: 401.
    Unauthenticated,
    /// A cookie session's state-changing request without its CSRF token: 403.
    NoCsrf,
}

fn random_hex() -> String {
    let mut bytes = [0u8; 16];
    rand::rng().fill_bytes(&mut bytes);
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The token matches, in constant time (its length aside).
pub fn token_matches(given: &str, token: &str) -> bool {
    !token.is_empty() && bool::from(given.as_bytes().ct_eq(token.as_bytes()))
}

impl Sessions {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Session>> {
        self.sessions.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A new session; its id (the cookie's value).
    pub fn open(&self) -> String {
        let id = random_hex();
        let mut sessions = self.lock();
        sessions.retain(|_, s| s.since.elapsed() < SESSION_LIFETIME);
        if sessions.len() >= MAX_SESSIONS
            && let Some(oldest) = sessions
                .iter()
                .min_by_key(|(_, s)| s.since)
                .map(|(k, _)| k.clone())
        {
            sessions.remove(&oldest);
        }
        sessions.insert(
            id.clone(),
            Session {
                csrf: random_hex(),
                since: Instant::now(),
            },
        );
        id
    }

    /// Ends the session `id`.
    pub fn close(&self, id: &str) {
        self.lock().remove(id);
    }

    /// The CSRF token of a live session.
    fn csrf(&self, id: &str) -> Option<String> {
        let sessions = self.lock();
        let s = sessions.get(id)?;
        (s.since.elapsed() < SESSION_LIFETIME).then(|| s.csrf.clone())
    }

    /// Who sent `headers`, checked for `method`: a bearer token first, then the cookie (and,
    /// for a state-changing method, its CSRF header).
    pub fn check(&self, token: &str, method: &Method, headers: &HeaderMap) -> Result<Who, Denied> {
        if let Some(bearer) = headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "))
        {
            return if token_matches(bearer.trim(), token) {
                Ok(Who::Bearer)
            } else {
                Err(Denied::Unauthenticated)
            };
        }
        let csrf = session_id(headers)
            .and_then(|id| self.csrf(&id))
            .ok_or(Denied::Unauthenticated)?;
        let safe = matches!(*method, Method::GET | Method::HEAD);
        if !safe {
            let sent = headers.get(CSRF_HEADER).and_then(|v| v.to_str().ok());
            if !sent.is_some_and(|s| bool::from(s.as_bytes().ct_eq(csrf.as_bytes()))) {
                return Err(Denied::NoCsrf);
            }
        }
        Ok(Who::Session { csrf })
    }
}

/// The session id in a request's cookies.
pub fn session_id(headers: &HeaderMap) -> Option<String> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|pair| pair.trim().split_once('='))
        .find(|(name, _)| *name == COOKIE)
        .map(|(_, value)| value.to_string())
}

/// The `Set-Cookie` value of a new session.
pub fn cookie(id: &str) -> String {
    format!(
        "{COOKIE}={id}; HttpOnly; SameSite=Strict; Path=/; Max-Age={}",
        SESSION_LIFETIME.as_secs()
    )
}

/// The `Set-Cookie` value that ends a session in the browser.
pub fn expired_cookie() -> String {
    format!("{COOKIE}=; HttpOnly; SameSite=Strict; Path=/; Max-Age=0")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.append(*k, v.parse().expect("header value"));
        }
        h
    }

    /// A bearer token works for every method; a wrong one does not; a cookie session reads
    /// freely but changes nothing without its own CSRF token; a closed session is gone.
    #[test]
    fn tokens_sessions_and_csrf() {
        let s = Sessions::default();
        let bearer = headers(&[("authorization", "Bearer secret")]);
        assert_eq!(s.check("secret", &Method::POST, &bearer), Ok(Who::Bearer));
        let wrong = headers(&[("authorization", "Bearer nope")]);
        assert_eq!(
            s.check("secret", &Method::GET, &wrong),
            Err(Denied::Unauthenticated)
        );
        assert_eq!(
            s.check("secret", &Method::GET, &HeaderMap::new()),
            Err(Denied::Unauthenticated)
        );
        let id = s.open();
        let cookie = format!("other=1; {COOKIE}={id}");
        let browser = headers(&[("cookie", &cookie)]);
        let Ok(Who::Session { csrf }) = s.check("secret", &Method::GET, &browser) else {
            panic!("the session reads");
        };
        assert_eq!(
            s.check("secret", &Method::POST, &browser),
            Err(Denied::NoCsrf)
        );
        let forged = headers(&[("cookie", &cookie), (CSRF_HEADER, "0000")]);
        assert_eq!(
            s.check("secret", &Method::PUT, &forged),
            Err(Denied::NoCsrf)
        );
        let good = headers(&[("cookie", &cookie), (CSRF_HEADER, &csrf)]);
        assert!(s.check("secret", &Method::POST, &good).is_ok());
        s.close(&id);
        assert_eq!(
            s.check("secret", &Method::GET, &browser),
            Err(Denied::Unauthenticated)
        );
        // An empty configured token never matches.
        assert!(!token_matches("", ""));
    }

    /// Past the limit, the oldest session ends.
    #[test]
    fn sessions_are_bounded() {
        let s = Sessions::default();
        let first = s.open();
        for _ in 0..MAX_SESSIONS {
            s.open();
        }
        assert_eq!(s.lock().len(), MAX_SESSIONS);
        assert!(s.csrf(&first).is_none());
    }
}
