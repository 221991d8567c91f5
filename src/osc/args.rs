//! The argument rules of docs/osc.md as small pure functions, so every address reads its
//! arguments the same way and refuses them with the same kind of sentence.
//!
//! - Numbers arrive as int32, int64, float32, float64 or (Eos) a string that parses as one.
//! - Trailing numeric path segments are arguments: `/vo/pick/3` is `/vo/pick 3`.
//! - Addresses match case-insensitively.
//! - A trigger arriving with a single numeric 0 is a button release, ignored silently.

use std::sync::atomic::{AtomicUsize, Ordering};

use rosc::{OscMessage, OscType};

/// The addresses that take no argument (docs/osc.md), as [`Request::matches`] patterns: a
/// single numeric 0 sent to one of these is a button release.
pub const TRIGGERS: &[&str] = &[
    "/vo/generate",
    "/vo/next",
    "/vo/prev",
    "/vo/undo",
    "/vo/redo",
    "/vo/gallery",
    "/vo/live",
    "/vo/looks",
    "/vo/status",
    "/vo/console/selection",
    "/vo/objectives",
    "/vo/objective/clear",
    "/vo/console/grab",
    "/vo/objective/*/palette",
    "/vo/objective/*/remove",
    "/vo/unsubscribe",
    "/vo/constraints",
    "/vo/pins",
    "/vo/pin/*/remove",
];

/// A message as the commands read it: the address split into lowercase segments, with
/// trailing numeric segments moved to the front of the arguments.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    /// The address as received, for the `/vo/error` that names it.
    pub addr: String,
    /// Lowercase path segments (`/VO/Pick/3` gives `["vo", "pick"]`).
    pub segments: Vec<String>,
    /// The arguments, trailing path numbers first (read through [`Request::arg`] and
    /// [`Request::args`], which count what the command read).
    args: Vec<OscType>,
    /// How many of `args` came from the path.
    from_path: usize,
    /// How many arguments the command read: any after them are extra ([`Request::extra`]).
    read: Reads,
}

/// The highest argument index read, plus one. Cloned by value; never part of equality.
#[derive(Debug, Default)]
struct Reads(AtomicUsize);

impl Clone for Reads {
    fn clone(&self) -> Self {
        Reads(AtomicUsize::new(self.0.load(Ordering::Relaxed)))
    }
}

impl PartialEq for Reads {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Request {
    /// Reads a received message by the rules above (once, on the way in: the server, the
    /// commands and the handler all see this same value).
    pub fn new(msg: OscMessage) -> Request {
        let mut segments: Vec<String> = msg
            .addr
            .split('/')
            .filter(|s| !s.is_empty())
            .map(str::to_lowercase)
            .collect();
        let numeric = segments
            .iter()
            .rev()
            .take_while(|s| parse_number(s).is_some())
            .count();
        let mut args: Vec<OscType> = segments
            .split_off(segments.len() - numeric)
            .iter()
            .map(|s| match s.parse::<i32>() {
                Ok(i) => OscType::Int(i),
                Err(_) => OscType::Double(parse_number(s).unwrap_or_default()),
            })
            .collect();
        let from_path = args.len();
        args.extend(msg.args);
        Request {
            addr: msg.addr,
            segments,
            args,
            from_path,
            read: Reads::default(),
        }
    }

    /// The message as received (its address whole, only the arguments it carried), for
    /// what is handed on rather than read (Eos's answers to an export).
    pub fn message(&self) -> OscMessage {
        OscMessage {
            addr: self.addr.clone(),
            args: self.args()[self.from_path..].to_vec(),
        }
    }

    /// Argument `i` (counted as read, present or not: an optional argument was looked at).
    pub fn arg(&self, i: usize) -> Option<&OscType> {
        self.read.0.fetch_max(i + 1, Ordering::Relaxed);
        self.args.get(i)
    }

    /// Argument `i`, which the command needs: a sentence naming `what` when it is missing.
    pub fn required(&self, i: usize, what: &str) -> Result<&OscType, String> {
        self.arg(i)
            .ok_or_else(|| format!("missing {what} (argument {})", i + 1))
    }

    /// Every argument (all counted as read: the command takes any number).
    pub fn args(&self) -> &[OscType] {
        self.read.0.fetch_max(self.args.len(), Ordering::Relaxed);
        &self.args
    }

    /// After a command parsed: the sentence for arguments it did not read, which would
    /// otherwise be ignored silently (`/vo/fade 2 3`). A trigger takes one argument of any
    /// value (a button's press) and no more.
    pub fn extra(&self) -> Option<String> {
        let trigger = TRIGGERS.iter().any(|t| self.matches(t).is_some());
        let read = self
            .read
            .0
            .load(Ordering::Relaxed)
            .max(usize::from(trigger));
        (self.args.len() > read).then(|| {
            let takes = match read {
                0 => "takes no arguments".to_string(),
                1 => "takes 1 argument".to_string(),
                n => format!("takes at most {n} arguments"),
            };
            format!(
                "{} {takes}, got {}: the extra ones would be ignored (docs/osc.md)",
                self.path(),
                self.args.len()
            )
        })
    }

    /// The address without its trailing numbers, lowercase (`/vo/pick`).
    pub fn path(&self) -> String {
        format!("/{}", self.segments.join("/"))
    }

    /// Matches a lowercase pattern where `*` stands for one segment, returning what each `*`
    /// matched: `/vo/light/*/level` against `/VO/Light/12/Level` gives `["12"]`.
    pub fn matches(&self, pattern: &str) -> Option<Vec<&str>> {
        let pattern: Vec<&str> = pattern.split('/').filter(|s| !s.is_empty()).collect();
        if pattern.len() != self.segments.len() {
            return None;
        }
        let mut captures = Vec::new();
        for (p, s) in pattern.iter().zip(&self.segments) {
            if *p == "*" {
                captures.push(s.as_str());
            } else if p != s {
                return None;
            }
        }
        Some(captures)
    }

    /// Whether this is a button release: a [`TRIGGERS`] address with exactly one numeric
    /// argument equal to 0 (answered with nothing).
    pub fn is_button_release(&self) -> bool {
        let zero = match self.args.as_slice() {
            [arg] => number_of(arg) == Some(0.0),
            _ => false,
        };
        zero && self.is_trigger()
    }

    /// Whether the address is one of [`TRIGGERS`].
    fn is_trigger(&self) -> bool {
        TRIGGERS.iter().any(|t| self.matches(t).is_some())
    }
}

/// Reads a number: int32, int64, float32, float64, or a string holding one. NaN and
/// infinities are refused. `what` names the argument in the error ("fade seconds").
pub fn number(arg: &OscType, what: &str) -> Result<f64, String> {
    let non_finite = |v: f64| format!("expected a finite number for {what}, got {v}");
    match arg {
        OscType::Int(i) => Ok(f64::from(*i)),
        OscType::Long(i) => Ok(*i as f64),
        OscType::Float(f) if f.is_finite() => Ok(f64::from(*f)),
        OscType::Double(d) if d.is_finite() => Ok(*d),
        OscType::Float(f) => Err(non_finite(f64::from(*f))),
        OscType::Double(d) => Err(non_finite(*d)),
        OscType::String(s) => match s.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!(
                "expected a number for {what}, got {}",
                describe(arg)
            )),
        },
        other => Err(format!(
            "expected a number for {what}, got {}",
            describe(other)
        )),
    }
}

/// Reads a whole number (any accepted number form; `3.0` is 3, `3.5` is refused).
pub fn integer(arg: &OscType, what: &str) -> Result<i64, String> {
    let v = number(arg, what)?;
    if v.fract() != 0.0 || v.abs() > 9.0e15 {
        return Err(format!("expected a whole number for {what}, got {v}"));
    }
    Ok(v as i64)
}

/// Reads a number and checks it lies in `min..=max`.
pub fn number_in(arg: &OscType, what: &str, min: f64, max: f64) -> Result<f64, String> {
    let v = number(arg, what)?;
    if !(min..=max).contains(&v) {
        return Err(format!("{what} must be {min}..={max}, got {v}"));
    }
    Ok(v)
}

/// Reads an on/off switch: 0 or 1 in any number form, or an OSC true/false.
pub fn switch(arg: &OscType, what: &str) -> Result<bool, String> {
    if let OscType::Bool(b) = arg {
        return Ok(*b);
    }
    match number(arg, what)? {
        0.0 => Ok(false),
        1.0 => Ok(true),
        v => Err(format!("{what} must be 0 or 1, got {v}")),
    }
}

/// Reads a name (a group, an image file): a string argument.
pub fn string<'a>(arg: &'a OscType, what: &str) -> Result<&'a str, String> {
    match arg {
        OscType::String(s) => Ok(s),
        other => Err(format!(
            "expected a string for {what}, got {}",
            describe(other)
        )),
    }
}

/// The argument at `index`, or an error naming what is missing.
/// An argument as a person would name it in an error: `the string "fast"`, `the int 3`.
pub fn describe(arg: &OscType) -> String {
    match arg {
        OscType::Int(i) => format!("the int {i}"),
        OscType::Long(i) => format!("the int64 {i}"),
        OscType::Float(f) => format!("the float {f}"),
        OscType::Double(d) => format!("the double {d}"),
        OscType::String(s) => format!("the string {s:?}"),
        OscType::Blob(b) => format!("a blob of {} bytes", b.len()),
        OscType::Time(_) => "a time tag".into(),
        OscType::Char(c) => format!("the character {c:?}"),
        OscType::Color(_) => "a colour".into(),
        OscType::Midi(_) => "a MIDI message".into(),
        OscType::Bool(b) => format!("{b}"),
        OscType::Array(_) => "an array".into(),
        OscType::Nil => "nil".into(),
        OscType::Inf => "infinitum".into(),
    }
}

fn number_of(arg: &OscType) -> Option<f64> {
    number(arg, "").ok()
}

fn parse_number(s: &str) -> Option<f64> {
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(addr: &str, args: Vec<OscType>) -> Request {
        Request::new(OscMessage {
            addr: addr.into(),
            args,
        })
    }

    #[test]
    fn numbers_in_every_form() {
        for a in [
            OscType::Int(3),
            OscType::Long(3),
            OscType::Float(3.0),
            OscType::Double(3.0),
            OscType::String(" 3 ".into()),
        ] {
            assert_eq!(number(&a, "x"), Ok(3.0), "{a:?}");
            assert_eq!(integer(&a, "x"), Ok(3));
        }
        assert_eq!(
            number(&OscType::String("fast".into()), "fade seconds").unwrap_err(),
            "expected a number for fade seconds, got the string \"fast\""
        );
        for bad in [
            OscType::Float(f32::NAN),
            OscType::Double(f64::INFINITY),
            OscType::String("NaN".into()),
            OscType::String("inf".into()),
        ] {
            assert!(number(&bad, "level").is_err(), "{bad:?}");
        }
        assert!(
            number(&OscType::Float(f32::NAN), "level")
                .unwrap_err()
                .contains("finite")
        );
        assert!(
            integer(&OscType::Float(2.5), "entry")
                .unwrap_err()
                .contains("whole")
        );
        assert_eq!(
            number_in(&OscType::Int(700), "fade seconds", 0.0, 600.0).unwrap_err(),
            "fade seconds must be 0..=600, got 700"
        );
        assert_eq!(switch(&OscType::String("1".into()), "lock"), Ok(true));
        assert_eq!(switch(&OscType::Bool(false), "lock"), Ok(false));
        assert!(switch(&OscType::Int(2), "lock").is_err());
        assert_eq!(string(&OscType::String("a b".into()), "image"), Ok("a b"));
        assert_eq!(
            string(&OscType::Int(4), "image").unwrap_err(),
            "expected a string for image, got the int 4"
        );
        assert_eq!(
            req("/vo/pick", vec![]).required(0, "an entry").unwrap_err(),
            "missing an entry (argument 1)"
        );
    }

    #[test]
    fn trailing_numbers_become_arguments() {
        let r = req("/VO/Pick/3", vec![]);
        assert_eq!(r.segments, ["vo", "pick"]);
        assert_eq!(r.args, [OscType::Int(3)]);
        assert_eq!(r.path(), "/vo/pick");
        let r = req("/vo/pick/3/2", vec![OscType::Int(9)]);
        assert_eq!(r.args, [OscType::Int(3), OscType::Int(2), OscType::Int(9)]);
        let r = req("/vo/master/0.5", vec![]);
        assert_eq!(r.args, [OscType::Double(0.5)]);
        let r = req("/vo/light/12/level", vec![OscType::Float(50.0)]);
        assert_eq!(r.segments, ["vo", "light", "12", "level"]);
        assert_eq!(r.matches("/vo/light/*/level"), Some(vec!["12"]));
        assert_eq!(r.matches("/vo/light/*/color"), None);
        assert_eq!(r.matches("/vo/light/*"), None);
        assert_eq!(
            req("/vo/Group/Front/KEY", vec![]).matches("/vo/group/*/key"),
            Some(vec!["front"])
        );
    }

    #[test]
    fn button_releases() {
        assert!(req("/vo/generate", vec![OscType::Float(0.0)]).is_button_release());
        assert!(req("/vo/Next/0", vec![]).is_button_release());
        assert!(
            req("/vo/objective/2/remove", vec![OscType::String("0".into())]).is_button_release()
        );
        assert!(!req("/vo/generate", vec![OscType::Float(1.0)]).is_button_release());
        assert!(!req("/vo/generate", vec![]).is_button_release());
        assert!(!req("/vo/generate", vec![OscType::Int(0), OscType::Int(0)]).is_button_release());
        assert!(!req("/vo/master", vec![OscType::Int(0)]).is_button_release());
        assert!(!req("/vo/next", vec![OscType::String("off".into())]).is_button_release());
    }
}
