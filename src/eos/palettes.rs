//! The focus palettes an Eos console has, read over OSC: `/eos/get/fp/count`, then
//! `/eos/get/fp/index/<i>` for every index (a window ahead of the answers), each answered
//! by a palette's list (label) and its channel list (the reply formats are the rig
//! crate's `eos` module). `visobjd import eos://` lists them and names the scene's
//! positions after them; the Eos export asks before recording, so a position goes out as
//! `Focus_Palette n` only where the console has palette n (docs/eos.md).

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use rosc::OscMessage;
use visobjd_rig::eos::{self, Arg, EosPalette, Lists, PaletteList, Reply};

use super::link::arg;

/// The most focus palettes read: Eos holds up to 1,000 of each palette type (Eos Family
/// manual, "About Palettes"), so a larger count is not a console's.
pub const MAX_PALETTES: usize = 1000;

/// Index requests out at once.
const WINDOW: usize = 32;

/// A way to the console and back: the import's TCP link, or the export's channel.
pub trait Exchange {
    /// Sends the messages in order.
    fn send(&mut self, messages: &[OscMessage]) -> Result<(), String>;
    /// The next message from the console, None once `deadline` passes without one.
    fn next(&mut self, deadline: Instant) -> Result<Option<OscMessage>, String>;
}

/// The palette numbers the console has, as a scene numbers them (decimal ones left out).
pub fn numbers(palettes: &[EosPalette]) -> BTreeSet<u32> {
    palettes.iter().filter_map(EosPalette::whole).collect()
}

/// Reads every focus palette; `quiet` is the longest the console may be silent. Err names
/// what was being read when the console stopped answering or sent what is not a palette.
pub fn read(ex: &mut dyn Exchange, quiet: Duration) -> Result<Vec<EosPalette>, String> {
    let request = |addr: String| OscMessage {
        addr,
        args: Vec::new(),
    };
    let next = |ex: &mut dyn Exchange, what: &dyn Fn() -> String| {
        ex.next(Instant::now() + quiet)?.ok_or_else(|| {
            format!(
                "Eos did not answer within {} s while reading {}",
                quiet.as_secs_f64(),
                what()
            )
        })
    };
    ex.send(&[request("/eos/get/fp/count".into())])?;
    let n = loop {
        let m = next(ex, &|| "the focus palette count".into())?;
        if eos::reply(&m.addr) == Reply::PaletteCount {
            let args: Vec<Arg> = m.args.iter().map(arg).collect();
            break eos::first_number(&args)
                .ok_or_else(|| format!("{} carries no count", m.addr))?;
        }
    };
    if n > MAX_PALETTES {
        return Err(format!(
            "Eos reports {n} focus palettes; a console holds at most {MAX_PALETTES}"
        ));
    }
    let mut lists = Lists::default();
    // By index: the palette's number and list, and its channel list.
    let mut mains: BTreeMap<usize, (String, Vec<Arg>)> = BTreeMap::new();
    let mut members: BTreeMap<usize, Vec<Arg>> = BTreeMap::new();
    let (mut sent, mut done) = (0, 0);
    while done < n {
        let upto = n.min(done + WINDOW);
        if sent < upto {
            let batch: Vec<OscMessage> = (sent..upto)
                .map(|i| request(format!("/eos/get/fp/index/{i}")))
                .collect();
            ex.send(&batch)?;
            sent = upto;
        }
        let m = next(ex, &|| format!("the focus palettes ({done} of {n} in)"))?;
        let Reply::Palette {
            number,
            list,
            piece,
        } = eos::reply(&m.addr)
        else {
            continue;
        };
        if list == PaletteList::ByType {
            continue;
        }
        let key = format!("fp/{number}/{list:?}");
        let Some(whole) = lists.add(&key, piece, m.args.iter().map(arg).collect())? else {
            continue;
        };
        let Some(i) = eos::first_number(&whole).filter(|&i| i < n) else {
            return Err(format!(
                "{}: the focus palette list's index is not one of 0..{n}",
                m.addr
            ));
        };
        let first = if list == PaletteList::Channels {
            members.insert(i, whole).is_none()
        } else {
            mains.insert(i, (number, whole)).is_none()
        };
        if first && mains.contains_key(&i) && members.contains_key(&i) {
            done += 1;
        }
    }
    mains
        .iter()
        .map(|(i, (number, list))| {
            let channels = members.get(i).map(Vec::as_slice).unwrap_or_default();
            eos::palette_entry(number, list, channels)
        })
        .collect()
}
