//! Who may reach the page, checked on every request ([`guard`]), in order: the `osc.allow`
//! list on accept (before a byte is read, in `super::accept`); the `Host` must be an
//! address, `localhost` or a name in `[http] hosts` (a page on another site that rebinds its
//! own name to the booth's address cannot reach it); the optional password (`[http]
//! password`, HTTP Basic); and on every state change (anything but GET and HEAD) the
//! `Origin` and `Sec-Fetch-Site` a browser sends must be this page's own. GET never changes
//! anything.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::Response;
use base64::Engine as _;

use super::{Client, Shared, refuse};
use crate::config::Config;

/// Who may reach the page besides the allow-list (`[http]`, docs/web.md).
#[derive(Debug, Clone, Default)]
pub(super) struct Access {
    /// The password (HTTP Basic, any user name); `None`: none asked.
    pub password: Option<String>,
    /// Host names besides addresses and `localhost` the page may be opened by.
    pub hosts: Vec<String>,
}

impl Access {
    /// The `[http]` settings of `config` (read on every request: a reload applies at once).
    pub(super) fn of(config: &Config) -> Access {
        Access {
            password: (!config.http.password.is_empty()).then(|| config.http.password.clone()),
            hosts: config.http.hosts.clone(),
        }
    }
}

/// The access rules every request passes (module header), and headers every answer gets:
/// nothing cached, nothing sniffed, never framed by another page.
pub(super) async fn guard(State(sh): State<Arc<Shared>>, req: Request, next: Next) -> Response {
    let access = Access::of(&sh.engine.config());
    let client = req.extensions().get::<Client>().map(|c| c.0.ip());
    if let Some(ip) = client
        && let Some(wait) = sh.guesses.blocked(ip, Instant::now())
    {
        return refuse(
            StatusCode::TOO_MANY_REQUESTS,
            &format!(
                "too many wrong passwords from {ip}: try again in {} s",
                wait.as_secs().max(1)
            ),
        );
    }
    if let Err(refusal) = admit(&access, req.method(), req.headers()) {
        let from = req.extensions().get::<Client>().map(|c| c.0);
        // A wrong password given (not the browser's first request, which has none) counts
        // towards the sender's limit.
        if refusal.0 == StatusCode::UNAUTHORIZED
            && req.headers().contains_key(header::AUTHORIZATION)
            && let Some(ip) = client
        {
            sh.guesses.failed(ip, Instant::now());
        }
        tracing::info!(
            "http: {} {} from {from:?} refused: {}",
            req.method(),
            req.uri().path(),
            refusal.1
        );
        let mut r = refuse(refusal.0, &refusal.1);
        if refusal.0 == StatusCode::UNAUTHORIZED {
            r.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Basic realm=\"visobjd\", charset=\"UTF-8\""),
            );
        }
        return r;
    }
    let mut r = next.run(req).await;
    let h = r.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'self'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src 'self' blob:; frame-ancestors 'none'",
        ),
    );
    r
}

/// Wrong passwords a sender may give in [`GUESS_WINDOW`] before it is refused for that long.
const GUESSES: u32 = 10;
/// See [`GUESSES`].
const GUESS_WINDOW: Duration = Duration::from_secs(60);
/// Senders whose wrong passwords are counted at once; the oldest is forgotten past it.
const GUESSERS: usize = 1024;

/// Wrong passwords per sender: after [`GUESSES`] within [`GUESS_WINDOW`], every request
/// from it is refused (429) until the window has passed, so the password cannot be
/// guessed at network speed.
#[derive(Default)]
pub(super) struct Guesses(Mutex<HashMap<IpAddr, (u32, Instant)>>);

impl Guesses {
    fn failed(&self, ip: IpAddr, now: Instant) {
        let mut m = self.0.lock().unwrap_or_else(|p| p.into_inner());
        if m.len() >= GUESSERS
            && !m.contains_key(&ip)
            && let Some(oldest) = m.iter().min_by_key(|(_, (_, t))| *t).map(|(k, _)| *k)
        {
            m.remove(&oldest);
        }
        let e = m.entry(ip).or_insert((0, now));
        if now.duration_since(e.1) > GUESS_WINDOW {
            *e = (0, now);
        }
        e.0 += 1;
        if e.0 == GUESSES {
            tracing::warn!(
                "http: {GUESSES} wrong passwords from {ip}: refused for {} s",
                GUESS_WINDOW.as_secs()
            );
        }
    }

    /// How long `ip` is still refused for, if it is.
    fn blocked(&self, ip: IpAddr, now: Instant) -> Option<Duration> {
        let m = self.0.lock().unwrap_or_else(|p| p.into_inner());
        let (n, since) = *m.get(&ip)?;
        let left = GUESS_WINDOW.checked_sub(now.duration_since(since))?;
        (n >= GUESSES && !left.is_zero()).then_some(left)
    }
}

/// Whether a request may go on: Host, password, and for a state change its origin.
fn admit(
    access: &Access,
    method: &Method,
    headers: &HeaderMap,
) -> Result<(), (StatusCode, String)> {
    let text = |name: header::HeaderName| headers.get(name).and_then(|v| v.to_str().ok());
    let host = text(header::HOST).unwrap_or_default();
    if !host_allowed(host, &access.hosts) {
        return Err((
            StatusCode::FORBIDDEN,
            format!(
                "Host `{host}` is not this daemon: open the page by its IP address, localhost, or a name listed in [http] hosts"
            ),
        ));
    }
    if let Some(password) = &access.password {
        let given = text(header::AUTHORIZATION)
            .and_then(|v| v.strip_prefix("Basic "))
            .and_then(|b| {
                base64::engine::general_purpose::STANDARD
                    .decode(b.trim())
                    .ok()
            })
            .and_then(|raw| String::from_utf8(raw).ok());
        let ok = given
            .as_deref()
            .and_then(|up| up.split_once(':'))
            .is_some_and(|(_, p)| same(p.as_bytes(), password.as_bytes()));
        if !ok {
            return Err((
                StatusCode::UNAUTHORIZED,
                "the password is missing or wrong ([http] password)".into(),
            ));
        }
    }
    if method == Method::GET || method == Method::HEAD {
        return Ok(());
    }
    if let Some(origin) = text(header::ORIGIN)
        && !origin.eq_ignore_ascii_case(&format!("http://{host}"))
    {
        return Err((
            StatusCode::FORBIDDEN,
            format!(
                "a change from the page of `{origin}` is refused: only this daemon's own page may change the rig"
            ),
        ));
    }
    if let Some(site) = headers.get("sec-fetch-site").and_then(|v| v.to_str().ok())
        && site != "same-origin"
        && site != "none"
    {
        return Err((
            StatusCode::FORBIDDEN,
            format!("a {site} change is refused: only this daemon's own page may change the rig"),
        ));
    }
    Ok(())
}

/// A `Host` header naming an IP address, `localhost` or one of `hosts`, with any port.
fn host_allowed(host: &str, hosts: &[String]) -> bool {
    let name = match host.strip_prefix('[') {
        Some(rest) => match rest.split_once(']') {
            Some((v6, port)) if port.is_empty() || port.starts_with(':') => v6,
            _ => return false,
        },
        None => match host.rsplit_once(':') {
            Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
            Some(_) => return false,
            None => host,
        },
    };
    !name.is_empty()
        && (name.parse::<std::net::IpAddr>().is_ok()
            || name.eq_ignore_ascii_case("localhost")
            || hosts.iter().any(|h| h.eq_ignore_ascii_case(name)))
}

/// Equal bytes, in time that does not depend on where they differ.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_are_addresses_localhost_or_listed() {
        let listed = vec!["booth.local".to_string()];
        for ok in [
            "127.0.0.1:8080",
            "10.0.0.5",
            "[::1]:8080",
            "[fe80::1]",
            "localhost:80",
            "LOCALHOST",
            "booth.local:8080",
        ] {
            assert!(host_allowed(ok, &listed), "{ok}");
        }
        for bad in [
            "",
            "evil.example",
            "evil.example:8080",
            "127.0.0.1.evil.example",
            "[::1",
            "[::1]x",
            "localhost:http",
            ":8080",
        ] {
            assert!(!host_allowed(bad, &listed), "{bad}");
        }
    }

    #[test]
    fn state_changes_need_their_own_origin_and_the_password() {
        let access = Access {
            password: Some("stage left".into()),
            hosts: Vec::new(),
        };
        let headers = |pairs: &[(&'static str, &str)]| {
            let mut h = HeaderMap::new();
            for (k, v) in pairs {
                h.insert(*k, HeaderValue::from_str(v).unwrap());
            }
            h
        };
        let auth = format!(
            "Basic {}",
            base64::engine::general_purpose::STANDARD.encode("any:stage left")
        );
        let good = [("host", "127.0.0.1:8080"), ("authorization", auth.as_str())];
        assert!(admit(&access, &Method::POST, &headers(&good)).is_ok());
        let same = [
            good[0],
            good[1],
            ("origin", "http://127.0.0.1:8080"),
            ("sec-fetch-site", "same-origin"),
        ];
        assert!(admit(&access, &Method::POST, &headers(&same)).is_ok());
        let evil = [good[0], good[1], ("origin", "http://evil.example")];
        assert_eq!(
            admit(&access, &Method::POST, &headers(&evil))
                .unwrap_err()
                .0,
            StatusCode::FORBIDDEN
        );
        // A GET is not a change: another origin may load a picture.
        assert!(admit(&access, &Method::GET, &headers(&evil)).is_ok());
        let cross = [good[0], good[1], ("sec-fetch-site", "cross-site")];
        assert!(admit(&access, &Method::PUT, &headers(&cross)).is_err());
        let wrong = format!(
            "Basic {}",
            base64::engine::general_purpose::STANDARD.encode("any:stage right")
        );
        for auth in ["", "Basic", "Basic !!", wrong.as_str()] {
            let h = headers(&[good[0], ("authorization", auth)]);
            assert_eq!(
                admit(&access, &Method::GET, &h).unwrap_err().0,
                StatusCode::UNAUTHORIZED,
                "{auth}"
            );
        }
        let rebound = [("host", "evil.example:8080"), good[1]];
        assert_eq!(
            admit(&access, &Method::GET, &headers(&rebound))
                .unwrap_err()
                .0,
            StatusCode::FORBIDDEN
        );
    }
}
