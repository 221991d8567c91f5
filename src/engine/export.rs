//! Looks recorded into consoles. `/vo/ma3/preset`, `/vo/ma3/cue`: the live look stored on
//! a grandMA3 (sent, never confirmed: MA3 answers nothing over OSC). `/vo/eos/preset`,
//! `/vo/eos/cue`, `/vo/eos/cues`: looks recorded on an Eos console, on a thread of their own (an Eos console may be slow to connect and to answer), through
//! `crate::eos`'s commands, each confirmed by Eos's answer (src/eos/record.rs). One
//! export runs at a time: Eos's answers over UDP come through the OSC port
//! ([`Engine::eos_heard`]) and go to the export waiting for them.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rosc::{OscMessage, OscType};

use super::{Engine, Later, Refusal, msg};
use crate::eos::EosConfig;
use crate::eos::commands::{Cue, cue_commands, preset_commands};
use crate::eos::record::{Channel, Record, Target};
use crate::ma3::commands::{Target as Ma3Target, store_commands};
use visobjd_scene::Scene;
use visobjd_scene::look::{Look, LookFile};

/// What to record.
pub enum EosRecord {
    /// The live look as preset `n`.
    Preset(u32),
    /// The live look as a cue, labelled (by default with the name of the saved look it
    /// is, if it is one).
    Cue { cue: Cue, label: Option<String> },
    /// Every saved look in number order, one cue each from `first` on, labelled with
    /// the looks' labels.
    Cues { first: Cue },
}

/// Where Eos's answers go while an export waits for them; Some while one runs.
pub type EosAnswers = Arc<Mutex<Option<Sender<OscMessage>>>>;

impl Engine {
    /// Records on the configured Eos console; the answer (`/vo/eos/preset n lights`, one
    /// `/vo/eos/recorded list cue` per cue, or why Eos did not take it) goes to `answer`.
    pub fn eos_record(&self, what: EosRecord, answer: Later) -> Result<(), Refusal> {
        let config = self.config().eos.clone();
        let to = config.target().map_err(Refusal::conflict)?.ok_or_else(|| {
            Refusal::conflict(
                "no Eos console is configured: set [eos] address (and protocol) in the config",
            )
        })?;
        let stage = self.stage();
        let (pending, fade_s) = self.eos_records(what)?;
        let (tx, heard) = mpsc::channel();
        {
            let mut waiting = self.eos_answers.lock().unwrap_or_else(|p| p.into_inner());
            if waiting.is_some() {
                return Err(Refusal::conflict(
                    "an Eos export is running: send this again once it is answered",
                ));
            }
            *waiting = Some(tx);
        }
        let waiting = Arc::clone(&self.eos_answers);
        let started = self.threads.spawn("eos", move || {
            let result = Channel::open(&config, to, heard).and_then(|mut channel| {
                let console = console_palettes(&stage.scene, &config, &mut channel);
                let records: Vec<(Record, OscMessage)> = pending
                    .into_iter()
                    .map(|(p, reply)| (p.record(&stage.scene, fade_s, &console), reply))
                    .collect();
                let mut replies = Vec::with_capacity(records.len());
                for (record, reply) in &records {
                    if let Err(e) = channel.record(&config, record) {
                        let done = records[..replies.len()]
                            .iter()
                            .map(|(r, _)| r.target.name())
                            .collect::<Vec<_>>();
                        return Err(if done.is_empty() {
                            e
                        } else {
                            format!("{e} (recorded before it: {})", done.join(", "))
                        });
                    }
                    replies.push(reply.clone());
                }
                Ok(replies)
            });
            *waiting.lock().unwrap_or_else(|p| p.into_inner()) = None;
            answer(result.map_err(|e| {
                tracing::warn!("Eos export: {e}");
                Refusal::internal(e)
            }));
        });
        started.map_err(|e| {
            *self.eos_answers.lock().unwrap_or_else(|p| p.into_inner()) = None;
            Refusal::internal(format!("cannot start the Eos export: {e}"))
        })
    }

    /// Stores the live look on the configured grandMA3 as `target` (a cue with the
    /// session's fade), labelled (by default as the saved look it is, if any); answers
    /// `/vo/ma3/sent what:s commands:i` once sent.
    pub fn ma3_store(
        &self,
        target: Ma3Target,
        label: Option<String>,
    ) -> Result<OscMessage, Refusal> {
        let config = self.config().ma3.clone();
        let to = config.target().map_err(Refusal::conflict)?.ok_or_else(|| {
            Refusal::conflict("no grandMA3 is configured: set [ma3] address in the config")
        })?;
        let stage = self.stage();
        let commands = {
            let s = self.session();
            let label = label.or_else(|| saved_label(&stage.scene, &s.looks, &s.live));
            store_commands(&stage.scene, &s.live, target, label.as_deref(), s.fade_s)
        };
        crate::ma3::send(&config, to, &commands).map_err(|e| {
            tracing::warn!("grandMA3 export: {e}");
            Refusal::internal(e)
        })?;
        Ok(msg(
            "/vo/ma3/sent",
            vec![
                OscType::String(target.to_string()),
                OscType::Int(commands.len() as i32),
            ],
        ))
    }

    /// An Eos message that came in on the OSC port (a command line echo or a read-back):
    /// to the export waiting for it, if one runs.
    pub fn eos_heard(&self, m: OscMessage) {
        let waiting = self.eos_answers.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(tx) = waiting.as_ref() {
            // The export may have ended meanwhile: nothing to hand it to.
            let _ = tx.send(m);
        }
    }

    /// The records `what` asks for, each with the reply that says it was confirmed, and
    /// the session's fade (a cue's time).
    fn eos_records(&self, what: EosRecord) -> Result<(Vec<(Pending, OscMessage)>, f32), Refusal> {
        let stage = self.stage();
        let scene = &stage.scene;
        let s = self.session();
        let cue_reply = |cue: Cue| {
            msg(
                "/vo/eos/recorded",
                vec![
                    OscType::Int(cue.list as i32),
                    OscType::Float(cue.number as f32),
                ],
            )
        };
        let cue = |cue: Cue, look: Look, label: Option<String>| {
            (
                Pending {
                    look,
                    target: Target::Cue(cue, label),
                },
                cue_reply(cue),
            )
        };
        let pending = match what {
            EosRecord::Preset(n) => vec![(
                Pending {
                    look: s.live.clone(),
                    target: Target::Preset(n),
                },
                msg(
                    "/vo/eos/preset",
                    vec![
                        OscType::Int(n as i32),
                        OscType::Int(scene.lights.len() as i32),
                    ],
                ),
            )],
            EosRecord::Cue { cue: c, label } => {
                let label = label.or_else(|| saved_label(scene, &s.looks, &s.live));
                vec![cue(c, s.live.clone(), label)]
            }
            EosRecord::Cues { first } => {
                if s.looks.is_empty() {
                    return Err(Refusal::conflict(
                        "there are no saved looks to record: save some with /vo/look/save first",
                    ));
                }
                let mut records = Vec::with_capacity(s.looks.len());
                for (i, file) in s.looks.values().enumerate() {
                    let c = first.after(i).map_err(|e| {
                        Refusal::input(format!(
                            "{} saved looks from cue {first}: {e}",
                            s.looks.len()
                        ))
                    })?;
                    let (look, _) = file.fit(scene);
                    records.push(cue(c, look, Some(file.label.clone())));
                }
                records
            }
        };
        Ok((pending, s.fade_s))
    }
}

/// A record still to be written: its command lines wait for the focus palettes the
/// console has, asked over the export's own connection.
struct Pending {
    look: Look,
    target: Target,
}

impl Pending {
    /// The record's command lines, `console` being the console's focus palettes.
    fn record(self, scene: &Scene, fade_s: f32, console: &BTreeSet<u32>) -> Record {
        let commands = match &self.target {
            Target::Preset(n) => preset_commands(scene, &self.look, *n, console),
            Target::Cue(cue, label) => {
                cue_commands(scene, &self.look, *cue, fade_s, label.as_deref(), console)
            }
        };
        Record {
            commands,
            target: self.target,
        }
    }
}

/// The focus palettes the console has, asked only when the scene has moving lights. A
/// console that does not say counts as having none: every position then goes as pan and
/// tilt, which is right on any console (docs/eos.md).
fn console_palettes(scene: &Scene, config: &EosConfig, channel: &mut Channel) -> BTreeSet<u32> {
    if !scene.lights.iter().any(|l| l.is_moving()) {
        return BTreeSet::new();
    }
    let quiet = Duration::from_secs_f64(config.timeout_s);
    match crate::eos::palettes::read(channel, quiet) {
        Ok(palettes) => crate::eos::palettes::numbers(&palettes),
        Err(e) => {
            tracing::warn!(
                "Eos export: the console's focus palettes: {e}; positions go as pan and tilt"
            );
            BTreeSet::new()
        }
    }
}

/// The label of the saved look `live` is, if it is one.
fn saved_label(scene: &Scene, looks: &BTreeMap<u32, LookFile>, live: &Look) -> Option<String> {
    let live = LookFile::from_look(scene, live, "");
    looks
        .values()
        .find(|f| f.lights == live.lights)
        .map(|f| f.label.clone())
}
