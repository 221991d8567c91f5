//! What a tablet is shown of the session, computed here so every transport shows the same:
//! `/vo/status` (the session and the output's health), the one-line `/vo/status/text`, the
//! gallery's sizes, and the entry buttons' lights. Pushed to subscribers on every change
//! ([`Engine::commit`]) and answered to queries.

use std::sync::atomic::Ordering;

use rosc::{OscMessage, OscType};

use super::session::{Gallery, Session};
use super::{Engine, msg};
use visobjd_dmx::input::SourceInfo;

impl Engine {
    /// `/vo/status` for `s`: the session, then the output's health (frames per second,
    /// late frames, failed sends, then a label and failed sends per destination).
    pub fn status(&self, s: &Session) -> OscMessage {
        let (candidates, clusters) = s
            .gallery
            .as_ref()
            .map_or((0, 0), |g| (g.generation.candidates.len(), g.len()));
        let health = self.output_stats();
        let stage = self.stage();
        let mut args = vec![
            OscType::String(stage.scene.name.clone()),
            OscType::Int(stage.scene.lights.len() as i32),
            OscType::Int(s.objectives.len() as i32),
            OscType::Int(candidates as i32),
            OscType::Int(clusters as i32),
            OscType::Int(s.entry.map_or(0, |(k, _)| k as i32)),
            OscType::Float(s.fade_s),
            OscType::Int(i32::from(s.blackout)),
            OscType::Float(s.master),
        ];
        if let Some(h) = health {
            args.extend([
                OscType::Float(h.tick_rate),
                OscType::Int(h.late_ticks.min(i32::MAX as u64) as i32),
                OscType::Int(h.send_errors.min(i32::MAX as u64) as i32),
            ]);
            for (name, errors) in h.destinations {
                args.push(OscType::String(name));
                args.push(OscType::Int(errors.min(i32::MAX as u64) as i32));
            }
        }
        if let Some(sources) = self.console_sources() {
            args.push(OscType::String("console".into()));
            args.push(OscType::Int(sources.len() as i32));
            for src in sources {
                args.extend([
                    OscType::String(src.name),
                    OscType::Int(i32::from(src.priority)),
                    OscType::String(universe_list(&src.universes)),
                    OscType::Float(src.age.as_secs_f32()),
                ]);
            }
        }
        if let Some(problem) = self.problems() {
            args.push(OscType::String("problem".into()));
            args.push(OscType::String(problem));
        }
        if !stage.unseen.is_empty() {
            args.push(OscType::String("unseen".into()));
            args.push(OscType::Int(stage.unseen.len() as i32));
            for u in &stage.unseen {
                args.push(OscType::Int(stage.scene.lights[u.light].channel as i32));
                args.push(OscType::String(u.error.to_string()));
            }
        }
        msg("/vo/status", args)
    }

    /// What keeps this daemon from doing its job, as one sentence: its scene did not load,
    /// or (a backup) it is not following its main.
    fn problems(&self) -> Option<String> {
        let all: Vec<String> = [self.scene_problem(), self.backup_problem()]
            .into_iter()
            .flatten()
            .collect();
        (!all.is_empty()).then(|| all.join("; "))
    }

    /// What a tablet shows of `s`, pushed to subscribers on every change so buttons and
    /// labels follow without scripts: `/vo/status`, the one-line `/vo/status/text`, the
    /// gallery sizes, and `/vo/entry/<k>/lit 0|1` for every entry (and for entries of a
    /// larger earlier gallery, turned off).
    pub fn feedback(&self, s: &Session) -> Vec<OscMessage> {
        let entries = s.gallery.as_ref().map_or(0, Gallery::len);
        let span = entries.max(self.pushes.lit_span.swap(entries, Ordering::SeqCst));
        let live = s.entry.map_or(0, |(k, _)| k);
        let mut out = vec![
            self.status(s),
            msg(
                "/vo/status/text",
                vec![OscType::String(self.status_text(s))],
            ),
            gallery_sizes(s),
        ];
        out.extend((1..=span).map(|k| {
            msg(
                &format!("/vo/entry/{k}/lit"),
                vec![OscType::Int(i32::from(k == live))],
            )
        }));
        out
    }

    /// One line a person reads on a tablet or the web page: what is live, how big the
    /// gallery is, what is running.
    pub fn status_text(&self, s: &Session) -> String {
        let mut parts = Vec::new();
        if let Some(problem) = self.problems() {
            parts.push(problem);
        }
        let stage = self.stage();
        if !stage.unseen.is_empty() {
            parts.push(format!(
                "left out (no basis image): {}",
                super::reload::unseen_list(&stage)
            ));
        }
        if s.blackout {
            parts.push("BLACKOUT".to_string());
        }
        if self.exploring() {
            parts.push("exploring...".to_string());
        } else if self.is_generating() {
            parts.push("generating...".to_string());
        }
        parts.push(match (&s.gallery, s.entry) {
            (None, _) => "no gallery yet".to_string(),
            (Some(g), Some((k, 1))) => format!("entry {k} of {} live", g.len()),
            (Some(g), Some((k, m))) => format!("entry {k}.{m} of {} live", g.len()),
            (Some(g), None) => format!("{} entries", g.len()),
        });
        let n = s.objectives.len();
        parts.push(format!("{n} objective{}", if n == 1 { "" } else { "s" }));
        parts.push(format!("fade {} s", s.fade_s));
        if s.master < 1.0 {
            parts.push(format!("master {:.0}%", s.master * 100.0));
        }
        if let Some(h) = self.output_stats() {
            parts.push(h.summary());
        }
        if let Some(sources) = self.console_sources() {
            parts.push(console_summary(&sources, s.following));
        }
        parts.join(", ")
    }
}

/// `/vo/gallery clusters size_1 ... size_c` (just `0` before the first generate).
pub fn gallery_sizes(s: &Session) -> OscMessage {
    let sizes: Vec<i32> = s
        .gallery
        .as_ref()
        .map(|g| {
            g.generation
                .entries
                .iter()
                .map(|e| e.len() as i32)
                .collect()
        })
        .unwrap_or_default();
    let mut a = vec![OscType::Int(sizes.len() as i32)];
    a.extend(sizes.into_iter().map(OscType::Int));
    msg("/vo/gallery", a)
}

/// Universes as status lists them: `1 2 5`.
fn universe_list(universes: &[u16]) -> String {
    universes
        .iter()
        .map(u16::to_string)
        .collect::<Vec<_>>()
        .join(" ")
}

/// The status line's console part: `console: Eos (100, u1 2, 0.1 s ago)`, `sampling` for a
/// source not counted yet, `following` while the base follows it.
fn console_summary(sources: &[SourceInfo], following: bool) -> String {
    let list = if sources.is_empty() {
        "no source".to_string()
    } else {
        sources
            .iter()
            .map(|s| {
                format!(
                    "{} ({}, u{}, {:.1} s ago{})",
                    s.name,
                    s.priority,
                    universe_list(&s.universes),
                    s.age.as_secs_f32(),
                    if s.active { "" } else { ", sampling" }
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    };
    let follow = if following { ", following" } else { "" };
    format!("console{follow}: {list}")
}
