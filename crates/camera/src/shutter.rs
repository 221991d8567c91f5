//! Shutter values as cameras spell them (`1/60`, `0.5`, `2`, `30`, `bulb`) and in seconds.

use std::fmt;

/// A shutter time: the camera's own spelling (what `--set-config shutterspeed=` needs) and
/// its nominal length in seconds (what a bracket is planned with). The frame's real
/// exposure comes from its EXIF, not from here.
#[derive(Debug, Clone, PartialEq)]
pub struct Shutter {
    text: String,
    seconds: f64,
}

impl Shutter {
    /// Reads a shutter choice: `1/60`, `0.5`, `2`, `30`, also `1/60s`, `2"` and `30s`
    /// as some bodies print them. `None` for `bulb`, `time`, `auto` and anything that is
    /// not a positive finite time.
    pub fn parse(choice: &str) -> Option<Shutter> {
        let trimmed = choice.trim();
        let number = trimmed
            .strip_suffix('s')
            .or_else(|| trimmed.strip_suffix('"'))
            .unwrap_or(trimmed)
            .trim();
        let seconds = match number.split_once('/') {
            Some((n, d)) => {
                let n: f64 = n.trim().parse().ok()?;
                let d: f64 = d.trim().parse().ok()?;
                n / d
            }
            None => number.parse().ok()?,
        };
        (seconds.is_finite() && seconds > 0.0).then(|| Shutter {
            text: trimmed.to_string(),
            seconds,
        })
    }

    /// A free shutter time for cameras without choices (the command camera): spelled as
    /// a decimal. `None` unless positive and finite.
    pub fn from_seconds(seconds: f64) -> Option<Shutter> {
        (seconds.is_finite() && seconds > 0.0).then(|| Shutter {
            text: decimal(seconds),
            seconds,
        })
    }

    /// The camera's spelling.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// Nominal seconds.
    pub fn seconds(&self) -> f64 {
        self.seconds
    }
}

impl fmt::Display for Shutter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// Seconds as a plain decimal (`0.016666667`, `2`): no exponent, so any program can read
/// it; nine decimals are finer than any shutter.
pub(crate) fn decimal(seconds: f64) -> String {
    let text = format!("{seconds:.9}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text.is_empty() {
        "0".to_string()
    } else {
        text.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_camera_spellings() {
        let s = |t: &str| Shutter::parse(t).map(|s| s.seconds());
        assert_eq!(s("1/60"), Some(1.0 / 60.0));
        assert_eq!(s("0.5"), Some(0.5));
        assert_eq!(s("2"), Some(2.0));
        assert_eq!(s("30"), Some(30.0));
        assert_eq!(s("1/4000s"), Some(1.0 / 4000.0));
        assert_eq!(s("2\""), Some(2.0));
        assert_eq!(s("bulb"), None);
        assert_eq!(s("Bulb"), None);
        assert_eq!(s("auto"), None);
        assert_eq!(s("1/0"), None);
        assert_eq!(s("0"), None);
        assert_eq!(s("-1"), None);
        assert_eq!(s(""), None);
        assert_eq!(
            Shutter::parse(" 1/60 ").map(|s| s.text().to_string()),
            Some("1/60".into())
        );
    }

    #[test]
    fn decimals_have_no_exponent() {
        assert_eq!(decimal(2.0), "2");
        assert_eq!(decimal(0.5), "0.5");
        assert_eq!(decimal(1.0 / 8000.0), "0.000125");
        assert_eq!(decimal(1.0 / 60.0), "0.016666667");
        assert_eq!(
            Shutter::from_seconds(0.25).map(|s| s.text().to_string()),
            Some("0.25".into())
        );
        assert!(Shutter::from_seconds(0.0).is_none());
        assert!(Shutter::from_seconds(f64::NAN).is_none());
    }
}
