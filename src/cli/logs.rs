//! Logging for every subcommand: `tracing` to stderr, filtered by `RUST_LOG` or the given
//! level. Under journald (`JOURNAL_STREAM` set and stderr not a terminal) each line starts
//! with its syslog priority (`<3>` error, `<4>` warning, `<6>` info, `<7>` debug), which
//! journald takes off and records, so `journalctl -p warning -u visobjd` shows warnings
//! and errors only; journald also stamps each line, so no second timestamp is written.

use std::fmt;

use tracing::{Event, Level, Subscriber};
use tracing_subscriber::fmt::format::{Format, Writer};
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields};
use tracing_subscriber::registry::LookupSpan;

/// Installs the global subscriber; `Err` says why `level` is not a filter.
pub fn init(level: &str) -> Result<(), String> {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .or_else(|_| tracing_subscriber::EnvFilter::try_new(level))
        .map_err(|e| format!("--log-level `{level}` is not a log filter: {e}"))?;
    let terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let journal = !terminal && std::env::var_os("JOURNAL_STREAM").is_some();
    let format = tracing_subscriber::fmt::format()
        .with_ansi(terminal)
        .with_target(false)
        .compact();
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    if journal {
        logs.event_format(Journal(format.without_time())).init();
    } else {
        logs.event_format(format).init();
    }
    Ok(())
}

/// The compact format behind a syslog priority prefix, for journald's stream reader.
struct Journal<T>(Format<tracing_subscriber::fmt::format::Compact, T>);

/// The syslog priority journald reads from a line's `<N>` prefix.
fn priority(level: &Level) -> u8 {
    match *level {
        Level::ERROR => 3,
        Level::WARN => 4,
        Level::INFO => 6,
        Level::DEBUG | Level::TRACE => 7,
    }
}

impl<S, N, T> FormatEvent<S, N> for Journal<T>
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
    Format<tracing_subscriber::fmt::format::Compact, T>: FormatEvent<S, N>,
{
    fn format_event(
        &self,
        ctx: &FmtContext<'_, S, N>,
        mut writer: Writer<'_>,
        event: &Event<'_>,
    ) -> fmt::Result {
        write!(writer, "<{}>", priority(event.metadata().level()))?;
        self.0.format_event(ctx, writer, event)
    }
}
