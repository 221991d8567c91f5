//! The `[backup]` section (docs/config.md): present, this daemon is a backup of a main and
//! sends the main's universes at a lower sACN priority (docs/reliability.md, "Backup").

use serde::Deserialize;

use visobjd_dmx::OutputConfig;

/// The `[backup]` section: present, this daemon is a backup of `main`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BackupConfig {
    /// The main's OSC TCP address (`osc.tcp` of its config), `host:port`.
    pub main: String,
    /// The sACN priority every destination sends at; by default each destination's
    /// configured priority minus 10. Always below the configured one.
    pub priority: Option<u8>,
}

/// How far below the configured (the main's) priority a backup sends by default.
const PRIORITY_STEP: u8 = 10;

/// Checks `[backup]` against `[output]` and lowers every sACN destination to the
/// backup's priority. Err is one sentence naming the key.
pub fn configure(backup: &BackupConfig, output: &mut OutputConfig) -> Result<(), String> {
    let main = backup.main.trim();
    let port_ok = main
        .rsplit_once(':')
        .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok_and(|p| p != 0));
    if !port_ok {
        return Err(format!(
            "backup.main `{}`: not host:port such as 10.101.0.10:8000 (the main's osc.tcp address)",
            backup.main
        ));
    }
    if !output.artnet.is_empty() {
        return Err("backup: a backup sends no Art-Net (Art-Net has no priority merge, so its ArtDmx would fight the main's); remove the [[output.artnet]] entries".into());
    }
    if output.sacn.is_empty() {
        return Err("backup: a backup takes over through sACN priority; list the main's [[output.sacn]] destinations".into());
    }
    if let Some(p) = backup.priority.filter(|&p| p > 200) {
        return Err(format!("backup.priority: {p} is out of range (0..=200)"));
    }
    for (i, d) in output.sacn.iter_mut().enumerate() {
        let lower = backup
            .priority
            .unwrap_or(d.priority.saturating_sub(PRIORITY_STEP));
        if lower >= d.priority {
            return Err(format!(
                "backup.priority {lower} is not below output.sacn[{i}].priority {}: a backup must send below the main, or it would fight it",
                d.priority
            ));
        }
        d.priority = lower;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use visobjd_dmx::{ArtnetDest, SacnDest};

    fn output(priorities: &[u8]) -> OutputConfig {
        OutputConfig {
            sacn: priorities
                .iter()
                .map(|&priority| SacnDest {
                    priority,
                    ..SacnDest::default()
                })
                .collect(),
            ..OutputConfig::default()
        }
    }

    fn backup(main: &str, priority: Option<u8>) -> BackupConfig {
        BackupConfig {
            main: main.into(),
            priority,
        }
    }

    #[test]
    fn a_backup_sends_below_each_destination() {
        let mut out = output(&[100, 5]);
        configure(&backup("10.0.0.1:8000", None), &mut out).unwrap();
        assert_eq!(out.sacn[0].priority, 90);
        assert_eq!(out.sacn[1].priority, 0);
        let mut out = output(&[100]);
        configure(&backup("main.local:8000", Some(50)), &mut out).unwrap();
        assert_eq!(out.sacn[0].priority, 50);
    }

    #[test]
    fn bad_backups_are_refused_with_the_key() {
        let e = configure(&backup("10.0.0.1", None), &mut output(&[100])).unwrap_err();
        assert!(e.contains("backup.main"), "{e}");
        let e = configure(&backup("10.0.0.1:8000", Some(100)), &mut output(&[100])).unwrap_err();
        assert!(e.contains("not below output.sacn[0].priority"), "{e}");
        let e = configure(&backup("10.0.0.1:8000", None), &mut output(&[0])).unwrap_err();
        assert!(e.contains("not below"), "{e}");
        let e = configure(&backup("10.0.0.1:8000", None), &mut output(&[])).unwrap_err();
        assert!(e.contains("[[output.sacn]]"), "{e}");
        let mut out = output(&[100]);
        out.artnet.push(ArtnetDest::default());
        let e = configure(&backup("10.0.0.1:8000", None), &mut out).unwrap_err();
        assert!(e.contains("no Art-Net"), "{e}");
    }
}
