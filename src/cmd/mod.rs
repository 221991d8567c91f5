//! The OSC address space (docs/osc.md) as commands. Each family of addresses is one file
//! with a `Cmd` enum, its `parse` (syntax: types and ranges; a failure is a
//! [`RefusalKind::Input`](crate::engine::RefusalKind)) and its `apply` (against the engine,
//! through a [`Context`]: existence, state changes, replies). [`Runner`] is the handler the
//! OSC server and the web page call; it parses a message once into a [`Command`] and
//! applies it. Calls go one way: transport -> `cmd` -> `engine`; the engine never calls
//! back.
//!
//! A new command family is one file plus its arms here: a `Command` variant, one line each
//! in `Command::parse`, `family`, `apply` and `changes_state`.
//!
//! A command that fails changes nothing and is answered with one `/vo/error`
//! ([`runner::render`]).

mod backup;
mod console;
mod constraint;
mod eos_in;
mod eos_out;
mod gallery;
mod generate;
mod live;
mod looks;
mod ma3;
mod objective;
mod position;
mod reload;
mod runner;
mod status;
mod suggest;
mod test_hook;
mod transfer;

pub use runner::Runner;

use std::collections::BTreeMap;
use std::sync::Arc;

use rosc::{OscMessage, OscType};

use crate::engine::session::Session;
use crate::engine::{Engine, Later, Outcome, Refusal};
use crate::osc::Peer;
use crate::osc::args::{self, Request};
use crate::osc::packet::{self, Item, PacketError};
use visobjd_scene::Scene;
use visobjd_scene::look::{Look, LookFile};

/// Every command the daemon understands.
enum Command {
    Backup(backup::Cmd),
    EosIn(eos_in::Cmd),
    EosOut(eos_out::Cmd),
    Objective(objective::Cmd),
    Position(position::Cmd),
    Constraint(constraint::Cmd),
    Console(console::Cmd),
    Generate(generate::Cmd),
    Gallery(gallery::Cmd),
    Live(live::Cmd),
    Looks(looks::Cmd),
    Ma3(ma3::Cmd),
    Reload(reload::Cmd),
    Status(status::Cmd),
    TestHook(test_hook::Cmd),
    Transfer(transfer::Cmd),
}

impl Command {
    /// The command `req` names; Err is the sentence for `/vo/error` (an input refusal),
    /// arguments the command does not take included.
    fn parse(req: &Request) -> Result<Command, String> {
        let command = Command::parse_family(req)?;
        match req.extra() {
            Some(extra) => Err(extra),
            None => Ok(command),
        }
    }

    /// The command of the family that knows `req`'s address.
    fn parse_family(req: &Request) -> Result<Command, String> {
        if let Some(c) = backup::Cmd::parse(req)? {
            return Ok(Command::Backup(c));
        }
        if let Some(c) = eos_in::Cmd::parse(req)? {
            return Ok(Command::EosIn(c));
        }
        if let Some(c) = eos_out::Cmd::parse(req)? {
            return Ok(Command::EosOut(c));
        }
        if let Some(c) = objective::Cmd::parse(req)? {
            return Ok(Command::Objective(c));
        }
        if let Some(c) = constraint::Cmd::parse(req)? {
            return Ok(Command::Constraint(c));
        }
        if let Some(c) = console::Cmd::parse(req)? {
            return Ok(Command::Console(c));
        }
        if let Some(c) = generate::Cmd::parse(req)? {
            return Ok(Command::Generate(c));
        }
        if let Some(c) = gallery::Cmd::parse(req)? {
            return Ok(Command::Gallery(c));
        }
        if let Some(c) = live::Cmd::parse(req)? {
            return Ok(Command::Live(c));
        }
        if let Some(c) = looks::Cmd::parse(req)? {
            return Ok(Command::Looks(c));
        }
        if let Some(c) = ma3::Cmd::parse(req)? {
            return Ok(Command::Ma3(c));
        }
        if let Some(c) = position::Cmd::parse(req)? {
            return Ok(Command::Position(c));
        }
        if let Some(c) = reload::Cmd::parse(req)? {
            return Ok(Command::Reload(c));
        }
        if let Some(c) = status::Cmd::parse(req)? {
            return Ok(Command::Status(c));
        }
        if let Some(c) = test_hook::Cmd::parse(req)? {
            return Ok(Command::TestHook(c));
        }
        if let Some(c) = transfer::Cmd::parse(req)? {
            return Ok(Command::Transfer(c));
        }
        let path = req.path();
        Err(match suggest::nearest(&path) {
            Some(meant) => format!(
                "unknown address {path}: did you mean {meant}? The addresses are listed in docs/osc.md"
            ),
            None => format!("unknown address {path}: the addresses are listed in docs/osc.md"),
        })
    }

    /// The address family, for [`parse`]'s callers.
    fn family(&self) -> &'static str {
        match self {
            Command::Backup(_) => "backup",
            Command::EosIn(_) => "eos",
            Command::EosOut(_) => "eos export",
            Command::Objective(_) => "objective",
            Command::Position(_) => "position",
            Command::Constraint(_) => "constraint",
            Command::Console(_) => "console",
            Command::Generate(_) => "generate",
            Command::Gallery(_) => "gallery",
            Command::Live(_) => "live",
            Command::Looks(_) => "looks",
            Command::Ma3(_) => "ma3",
            Command::Reload(_) => "reload",
            Command::Status(_) => "status",
            Command::TestHook(_) => "test",
            Command::Transfer(_) => "transfer",
        }
    }

    fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        match self {
            Command::Backup(c) => c.apply(cx),
            Command::EosIn(c) => c.apply(cx),
            Command::EosOut(c) => c.apply(cx),
            Command::Objective(c) => c.apply(cx),
            Command::Position(c) => c.apply(cx),
            Command::Constraint(c) => c.apply(cx),
            Command::Console(c) => c.apply(cx),
            Command::Generate(c) => c.apply(cx),
            Command::Gallery(c) => c.apply(cx),
            Command::Live(c) => c.apply(cx),
            Command::Looks(c) => c.apply(cx),
            Command::Ma3(c) => c.apply(cx),
            Command::Reload(c) => c.apply(cx),
            Command::Status(c) => c.apply(cx),
            Command::TestHook(c) => c.apply(cx),
            Command::Transfer(c) => c.apply(cx),
        }
    }

    /// Whether the command changes the session (the objectives, constraints, gallery,
    /// looks or stage): such commands are mirrored to a backup, and a backup refuses them
    /// from anyone but its main. Queries, subscriptions, pings and exports do not.
    fn changes_state(&self) -> bool {
        match self {
            Command::Backup(c) => c.changes_state(),
            Command::EosIn(c) => !matches!(
                c,
                eos_in::Cmd::Selection | eos_in::Cmd::EosOut(None) | eos_in::Cmd::EosAnswer(_)
            ),
            Command::Objective(c) => !matches!(
                c,
                objective::Cmd::Edit(objective::Edit::List | objective::Edit::Palette { .. })
            ),
            Command::Constraint(c) => !matches!(c, constraint::Cmd::Pins | constraint::Cmd::List),
            Command::Console(_) | Command::Generate(_) | Command::Transfer(_) => true,
            Command::Gallery(c) => {
                !matches!(c, gallery::Cmd::Candidate { .. } | gallery::Cmd::Gallery)
            }
            Command::Live(c) => !matches!(c, live::Cmd::Live),
            Command::Looks(c) => !matches!(c, looks::Cmd::List),
            // A reload changes this daemon's own files' view, not the mirrored session; a
            // learned palette is written into this daemon's own scene.toml.
            Command::EosOut(_)
            | Command::Ma3(_)
            | Command::Position(_)
            | Command::Reload(_)
            | Command::Status(_)
            | Command::TestHook(_) => false,
        }
    }

    /// Whether the command itself is forwarded to backups once the session took it. A
    /// generate is forwarded by the engine instead, as the gallery it installs
    /// (`/vo/backup/gallery`), and so are explore galleries (with their regions,
    /// src/engine/explore.rs); the backup's own messages are not forwarded.
    fn forwarded(&self) -> bool {
        self.changes_state()
            && !matches!(
                self,
                Command::Generate(
                    generate::Cmd::Generate | generate::Cmd::Seeded(_) | generate::Cmd::Explore(_)
                ) | Command::Backup(_)
            )
    }
}

/// What a command is applied with, as mini-redis hands its commands the `Db` and the
/// connection: the engine, the sender (an answer that comes later goes to it), and the
/// message a backup is forwarded when the session takes the change.
pub struct Context<'a> {
    engine: &'a Arc<Engine>,
    peer: &'a Peer,
    /// The address as received: a later answer's `/vo/error` names it.
    addr: &'a str,
    /// The command as received, if it is mirrored to backups ([`Command::forwarded`]).
    forward: Option<OscMessage>,
}

impl Context<'_> {
    /// [`Engine::commit`], forwarding this command to the backups if the change is taken.
    fn commit(
        &self,
        change: impl FnOnce(&mut Session) -> Result<Outcome, Refusal>,
    ) -> Result<Vec<OscMessage>, Refusal> {
        self.engine.commit(self.forward.as_ref(), change)
    }

    /// [`Engine::change_looks`], forwarding this command to the backups once written.
    fn change_looks<T>(
        &self,
        change: impl FnOnce(&Session, &mut BTreeMap<u32, LookFile>) -> Result<T, Refusal>,
    ) -> Result<T, Refusal> {
        self.engine.change_looks(self.forward.as_ref(), change)
    }

    /// Where an answer that comes after the command returned goes: to the sender, rendered
    /// as a reply is.
    fn later(&self) -> Later {
        let (peer, addr) = (self.peer.clone(), self.addr.to_string());
        Box::new(move |answer| {
            peer.reply(&runner::render(&addr, &peer, answer));
        })
    }
}

/// Reads one received packet (a datagram or a stream frame) the way the daemon does, up to
/// the commands and without an engine: for each message the server would hand on, the
/// command family it names or the sentence of its `/vo/error`. A pure function, so the
/// fuzz targets (fuzz/) and tests can drive the whole parsing path with arbitrary bytes.
pub fn parse(bytes: &[u8]) -> Result<Vec<Result<&'static str, String>>, PacketError> {
    Ok(packet::decode_items(bytes)?
        .into_iter()
        .filter_map(|item| match item {
            Item::Message(m) => {
                let req = Request::new(m);
                (!req.is_button_release()).then(|| Command::parse(&req).map(|c| c.family()))
            }
            Item::Malformed { why, .. } => Some(Err(why)),
        })
        .collect())
}

/// Argument `i` as a whole number in `min..=max`.
fn int_arg(req: &Request, i: usize, what: &str, min: i64, max: i64) -> Result<i64, String> {
    let v = args::integer(req.required(i, what)?, what)?;
    if !(min..=max).contains(&v) {
        return Err(format!("{what} must be {min}..={max}, got {v}"));
    }
    Ok(v)
}

/// Optional argument `i` as a whole number in `min..=max`, or `default`.
fn opt_int_arg(
    req: &Request,
    i: usize,
    what: &str,
    min: i64,
    max: i64,
    default: i64,
) -> Result<i64, String> {
    if req.arg(i).is_some() {
        int_arg(req, i, what, min, max)
    } else {
        Ok(default)
    }
}

/// Argument `i` as a number in `min..=max`.
fn num_arg(req: &Request, i: usize, what: &str, min: f64, max: f64) -> Result<f32, String> {
    args::number_in(req.required(i, what)?, what, min, max).map(|v| v as f32)
}

/// Arguments `i..i+3` as an sRGB colour, each 0..1.
fn rgb_args(req: &Request, i: usize) -> Result<[f32; 3], String> {
    Ok([
        num_arg(req, i, "red", 0.0, 1.0)?,
        num_arg(req, i + 1, "green", 0.0, 1.0)?,
        num_arg(req, i + 2, "blue", 0.0, 1.0)?,
    ])
}

/// Argument 0 as a 0/1 switch.
fn switch_arg(req: &Request, what: &str) -> Result<bool, String> {
    args::switch(req.required(0, what)?, what)
}

/// A group or a light, named as an address names it (`/vo/group/<name>/...`,
/// `/vo/light/<ch>/...`), resolved against the scene when the command is applied.
pub enum Named {
    Group(String),
    Light(String),
}

impl Named {
    /// `group` or `light`, as the address and its reply spell it.
    fn kind(&self) -> &'static str {
        match self {
            Named::Group(_) => "group",
            Named::Light(_) => "light",
        }
    }

    /// The lights it names, as indices (a light: one; a group: its lights).
    fn lights(&self, scene: &Scene) -> Result<Vec<usize>, Refusal> {
        Ok(match self {
            Named::Light(ch) => vec![light(scene, ch)?],
            Named::Group(name) => scene.groups[group(scene, name)?].lights.clone(),
        })
    }
}

/// The light with channel `segment`, as an index.
fn light(scene: &Scene, segment: &str) -> Result<usize, Refusal> {
    segment
        .parse::<u32>()
        .ok()
        .and_then(|ch| scene.light_index(ch))
        .ok_or_else(|| {
            Refusal::conflict(format!(
                "light {segment} is not in the scene ({})",
                scene.channel_range()
            ))
        })
}

/// The group called `name` (case-insensitive), as an index.
fn group(scene: &Scene, name: &str) -> Result<usize, Refusal> {
    scene.group_index(name).ok_or_else(|| {
        Refusal::conflict(format!(
            "group `{name}` is not in the scene (groups: {})",
            scene
                .groups
                .iter()
                .map(|g| g.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    })
}

/// `ch intensity r g b` for every light of `look`, in channel order.
fn light_args(scene: &Scene, look: &Look) -> Vec<OscType> {
    scene
        .lights
        .iter()
        .zip(&look.levels)
        .flat_map(|(light, lv)| one_light(light.channel, lv))
        .collect()
}

/// A look as replies list it: `addr head... ch intensity r g b ...`, then, on a rig with
/// moving lights, `addr/positions head... ch palette ...` (one pair per mover) so the
/// per-light lists keep their shape.
fn look_messages(addr: &str, head: Vec<OscType>, scene: &Scene, look: &Look) -> Vec<OscMessage> {
    let mut levels = head.clone();
    levels.extend(light_args(scene, look));
    let mut out = vec![crate::engine::msg(addr, levels)];
    if !scene.palettes.is_empty() {
        let mut positions = head;
        positions.extend(
            scene
                .lights
                .iter()
                .zip(&look.levels)
                .filter_map(|(light, lv)| Some((light.channel, light.position_of(lv)?.palette)))
                .flat_map(|(ch, n)| [OscType::Int(ch as i32), OscType::Int(n as i32)]),
        );
        out.push(crate::engine::msg(&format!("{addr}/positions"), positions));
    }
    out
}

fn one_light(channel: u32, lv: &visobjd_scene::look::Level) -> [OscType; 5] {
    [
        OscType::Int(channel as i32),
        OscType::Float(lv.intensity),
        OscType::Float(lv.color[0]),
        OscType::Float(lv.color[1]),
        OscType::Float(lv.color[2]),
    ]
}

fn int(v: usize) -> OscType {
    OscType::Int(v as i32)
}

fn text(s: &str) -> OscType {
    OscType::String(s.to_string())
}
