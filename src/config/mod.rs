//! `config/visobjd.toml` (docs/config.md): every key has a default, unknown keys are an error
//! naming the key and line, and relative paths are relative to the config file's folder.

use std::net::IpAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::eos::EosConfig;
use crate::ma3::Ma3Config;
use visobjd_dmx::{InputConfig, OutputConfig};
use visobjd_scene::describe_toml_error;

mod backup;
mod peers;

pub use backup::BackupConfig;
pub use peers::{PeerConfig, PeerFraming, validate_backups, validate_peers};

/// The whole configuration, paths resolved.
#[derive(Debug, Clone)]
pub struct Config {
    /// The file it came from (for messages).
    pub path: PathBuf,
    /// The scene folder.
    pub scene: PathBuf,
    /// The only folder objective images are read from.
    pub references: PathBuf,
    /// Saved looks, the live look, the sACN CID.
    pub state_dir: PathBuf,
    /// OSC listeners and access.
    pub osc: OscConfig,
    /// DMX outputs.
    pub output: OutputConfig,
    /// The console's DMX received (none by default).
    pub input: InputConfig,
    /// Generation defaults.
    pub generate: GenerateConfig,
    /// The Eos console presets are exported to (none by default).
    pub eos: EosConfig,
    /// The grandMA3 desk looks are stored on (none by default).
    pub ma3: Ma3Config,
    /// The web gallery (off by default).
    pub http: HttpConfig,
    /// `visobjd capture`'s settings.
    pub capture: CaptureConfig,
    /// `[backup]`: this daemon mirrors a main (none: it is a main, or alone).
    pub backup: Option<BackupConfig>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, default)]
struct ConfigFile {
    scene: PathBuf,
    references: PathBuf,
    state_dir: PathBuf,
    osc: OscConfig,
    output: OutputConfig,
    input: InputConfig,
    generate: GenerateConfig,
    eos: EosConfig,
    ma3: Ma3Config,
    http: HttpConfig,
    capture: CaptureConfig,
    backup: Option<BackupConfig>,
}

impl Default for ConfigFile {
    fn default() -> Self {
        ConfigFile {
            scene: "../scenes/demo".into(),
            references: "../scenes/demo/refs".into(),
            state_dir: "../state".into(),
            osc: OscConfig::default(),
            output: OutputConfig::default(),
            input: InputConfig::default(),
            generate: GenerateConfig::default(),
            eos: EosConfig::default(),
            ma3: Ma3Config::default(),
            http: HttpConfig::default(),
            capture: CaptureConfig::default(),
            backup: None,
        }
    }
}

/// The `[osc]` section.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OscConfig {
    /// UDP listen address; empty turns UDP off.
    pub udp: String,
    /// TCP listen address; empty turns TCP off.
    pub tcp: String,
    /// 0: reply to the sender's port; N: to the sender's address at port N.
    pub reply_port: u16,
    /// Senders allowed (addresses or CIDR blocks); empty: loopback only.
    pub allow: Vec<String>,
    /// `[[osc.peer]]`: where known clients get their replies and pushes.
    pub peer: Vec<PeerConfig>,
    /// The addresses this main's backups connect from: their TCP connections always get a
    /// slot, as the peers' do.
    pub backups: Vec<String>,
}

impl Default for OscConfig {
    fn default() -> Self {
        OscConfig {
            udp: "127.0.0.1:8000".into(),
            tcp: "127.0.0.1:8000".into(),
            reply_port: 0,
            allow: Vec::new(),
            peer: Vec::new(),
            backups: Vec::new(),
        }
    }
}

/// The `[http]` section: the web gallery (docs/web.md).
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HttpConfig {
    /// Listen address such as `127.0.0.1:8080`; empty (the default) turns it off. Its
    /// clients are checked against `osc.allow` like OSC senders.
    pub listen: String,
    /// The page's password (HTTP Basic, any user name); empty: none asked. At load, the
    /// content of `password_file` when that is set instead.
    pub password: String,
    /// A file holding the password (its first line), so it need not sit in the config;
    /// relative to the config's folder.
    pub password_file: String,
    /// Host names (besides addresses and `localhost`) the page may be opened by.
    pub hosts: Vec<String>,
}

/// The `[capture]` section (docs/capture.md).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CaptureConfig {
    /// The sACN priority capture sends at: above a console's 100, so the console can stay
    /// connected and takes the rig back when capture terminates its streams.
    pub priority: u8,
    /// Each camera call is killed after this many seconds and tried once more.
    pub camera_timeout_s: f64,
    /// How long a light is given to reach its level before the first frame.
    pub settle_s: f64,
    /// How long a moving light is given, dark, to reach a new position before it is lit
    /// and shot: a frame taken while it still moves shows it somewhere else.
    pub move_settle_s: f64,
}

impl Default for CaptureConfig {
    fn default() -> Self {
        CaptureConfig {
            priority: 200,
            camera_timeout_s: 60.0,
            settle_s: 1.0,
            move_settle_s: 2.0,
        }
    }
}

/// The `[generate]` section.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GenerateConfig {
    /// Candidates per generate (N), 1..=1000.
    pub count: u32,
    /// Gallery entries at most (c), 1..=64.
    pub clusters: u32,
    /// Key-light spread, fraction of full.
    pub sigma_key: f32,
    /// Fill-light spread, fraction of full.
    pub sigma_fill: f32,
    /// Colours per palette, 1..=16.
    pub palette: u32,
}

impl Default for GenerateConfig {
    fn default() -> Self {
        GenerateConfig {
            count: 100,
            clusters: 12,
            sigma_key: 0.05,
            sigma_fill: 0.10,
            palette: 5,
        }
    }
}

/// An address or CIDR block of the sender allow-list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cidr {
    /// Network address.
    pub addr: IpAddr,
    /// Prefix length.
    pub prefix: u8,
}

impl Cidr {
    /// Parses `10.0.0.5`, `10.0.0.0/24`, `::1` or `fd00::/8`.
    pub fn parse(s: &str) -> Result<Cidr, String> {
        let (addr, prefix) = match s.split_once('/') {
            Some((a, p)) => (a, Some(p)),
            None => (s, None),
        };
        let addr: IpAddr = addr
            .trim()
            .parse()
            .map_err(|_| format!("`{s}` is not an IP address or CIDR block"))?;
        let max = if addr.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            Some(p) => p
                .trim()
                .parse::<u8>()
                .ok()
                .filter(|&p| p <= max)
                .ok_or_else(|| format!("`{s}`: prefix length must be 0..={max}"))?,
            None => max,
        };
        Ok(Cidr { addr, prefix })
    }

    /// Whether `ip` is inside the block (IPv4-mapped IPv6 senders match IPv4 blocks).
    pub fn contains(&self, ip: IpAddr) -> bool {
        let ip = match ip {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
            v4 => v4,
        };
        match (self.addr, ip) {
            (IpAddr::V4(net), IpAddr::V4(a)) => {
                let mask = u32::MAX
                    .checked_shl(32 - u32::from(self.prefix))
                    .unwrap_or(0);
                u32::from(net) & mask == u32::from(a) & mask
            }
            (IpAddr::V6(net), IpAddr::V6(a)) => {
                let mask = u128::MAX
                    .checked_shl(128 - u32::from(self.prefix))
                    .unwrap_or(0);
                u128::from(net) & mask == u128::from(a) & mask
            }
            _ => false,
        }
    }
}

impl Config {
    /// Reads and validates a config file.
    pub fn load(path: &Path) -> Result<Config, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("{}: cannot read it: {e}", path.display()))?;
        Config::parse(path, &text)
    }

    /// Validates config text; `path` names the file and anchors relative paths.
    pub fn parse(path: &Path, text: &str) -> Result<Config, String> {
        let at = |m: String| format!("{}: {m}", path.display());
        let file: ConfigFile =
            toml::from_str(text).map_err(|e| at(describe_toml_error(text, &e)))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let resolve = |p: &Path| {
            if p.is_absolute() {
                p.to_path_buf()
            } else {
                dir.join(p)
            }
        };
        for (key, value) in [
            ("osc.udp", &file.osc.udp),
            ("osc.tcp", &file.osc.tcp),
            ("http.listen", &file.http.listen),
        ] {
            crate::osc::address(key, value, "127.0.0.1:8000").map_err(at)?;
        }
        let allow = file
            .osc
            .allow
            .iter()
            .map(|a| Cidr::parse(a).map_err(|e| at(format!("osc.allow: {e}"))))
            .collect::<Result<Vec<_>, _>>()?;
        validate_peers(&file.osc.peer, &allow).map_err(at)?;
        validate_backups(&file.osc.backups, &allow).map_err(at)?;
        if let Some(list) = file.input.sacn.as_ref().and_then(|s| s.allow.as_ref()) {
            for a in list {
                Cidr::parse(a).map_err(|e| at(format!("input.sacn.allow: {e}")))?;
            }
        }
        let g = &file.generate;
        let checks = [
            (
                (1..=1000).contains(&g.count),
                "generate.count must be 1..=1000",
            ),
            (
                (1..=64).contains(&g.clusters),
                "generate.clusters must be 1..=64",
            ),
            (
                (1..=crate::engine::session::MAX_PALETTE as u32).contains(&g.palette),
                "generate.palette must be 1..=16",
            ),
            (
                (0.0..=1.0).contains(&g.sigma_key),
                "generate.sigma_key must be 0..=1",
            ),
            (
                (0.0..=1.0).contains(&g.sigma_fill),
                "generate.sigma_fill must be 0..=1",
            ),
            (
                file.capture.priority <= 200,
                "capture.priority must be 0..=200 (E1.31)",
            ),
            (
                file.capture.camera_timeout_s.is_finite()
                    && (1.0..=3600.0).contains(&file.capture.camera_timeout_s),
                "capture.camera_timeout_s must be 1..=3600",
            ),
            (
                file.capture.settle_s.is_finite() && (0.0..=60.0).contains(&file.capture.settle_s),
                "capture.settle_s must be 0..=60",
            ),
            (
                file.capture.move_settle_s.is_finite()
                    && (0.0..=60.0).contains(&file.capture.move_settle_s),
                "capture.move_settle_s must be 0..=60",
            ),
        ];
        if let Some((_, m)) = checks.iter().find(|(ok, _)| !ok) {
            return Err(at((*m).to_string()));
        }
        file.eos.validate().map_err(at)?;
        file.ma3.validate().map_err(at)?;
        if let Some(sacn) = &file.input.sacn {
            sacn.addresses().map_err(at)?;
        }
        let mut http = file.http;
        if !http.password_file.is_empty() {
            if !http.password.is_empty() {
                return Err(at(
                    "http: set password or password_file, not both".to_string()
                ));
            }
            let p = resolve(Path::new(&http.password_file));
            let text = std::fs::read_to_string(&p).map_err(|e| {
                at(format!(
                    "http.password_file {}: cannot read it: {e}",
                    p.display()
                ))
            })?;
            http.password = text.lines().next().unwrap_or_default().to_string();
            if http.password.is_empty() {
                return Err(at(format!(
                    "http.password_file {}: its first line is empty",
                    p.display()
                )));
            }
        }
        let mut output = file.output;
        if let Some(backup) = &file.backup {
            backup::configure(backup, &mut output).map_err(at)?;
        }
        Ok(Config {
            path: path.to_path_buf(),
            scene: resolve(&file.scene),
            references: resolve(&file.references),
            state_dir: resolve(&file.state_dir),
            osc: file.osc,
            output,
            input: file.input,
            generate: file.generate,
            eos: file.eos,
            ma3: file.ma3,
            http,
            capture: file.capture,
            backup: file.backup,
        })
    }

    /// The allow-list, parsed (validated at load).
    pub fn allow_list(&self) -> Vec<Cidr> {
        parse_list(&self.osc.allow)
    }

    /// Who may feed the sACN input: `[input.sacn] allow`, else the OSC allow-list, with the
    /// same rule (empty: loopback only).
    pub fn input_allow_list(&self) -> Vec<Cidr> {
        match self.input.sacn.as_ref().and_then(|s| s.allow.as_ref()) {
            Some(list) => parse_list(list),
            None => self.allow_list(),
        }
    }
}

/// A list validated at load, parsed.
fn parse_list(list: &[String]) -> Vec<Cidr> {
    list.iter().filter_map(|a| Cidr::parse(a).ok()).collect()
}

/// Whether `ip` may talk to the daemon: on `allow` (addresses or CIDR blocks), or on
/// loopback when `allow` is empty. The web gallery uses it; OSC checks the same rule.
pub fn permits(allow: &[Cidr], ip: IpAddr) -> bool {
    if allow.is_empty() {
        match ip {
            IpAddr::V4(v4) => v4.is_loopback(),
            IpAddr::V6(v6) => v6
                .to_ipv4_mapped()
                .map_or(v6.is_loopback(), |v4| v4.is_loopback()),
        }
    } else {
        allow.iter().any(|c| c.contains(ip))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_backup_sends_below_the_main_and_no_art_net() {
        let path = Path::new("b.toml");
        let backup = "[backup]\nmain = \"10.0.0.1:8000\"\n";
        let c = Config::parse(path, &format!("{backup}[[output.sacn]]\npriority = 120\n")).unwrap();
        assert_eq!(c.output.sacn[0].priority, 110);
        assert_eq!(c.backup.map(|b| b.main), Some("10.0.0.1:8000".to_string()));
        let c = Config::parse(path, "[[output.sacn]]\npriority = 120\n").unwrap();
        assert_eq!((c.output.sacn[0].priority, c.backup), (120, None));
        let e = Config::parse(
            path,
            &format!("{backup}[[output.sacn]]\n[[output.artnet]]\n"),
        )
        .unwrap_err();
        assert!(
            e.starts_with("b.toml: backup: a backup sends no Art-Net"),
            "{e}"
        );
        let e = Config::parse(path, "[backup]\npriority = 5\n[[output.sacn]]\n").unwrap_err();
        assert!(e.contains("backup.main ``"), "{e}");
        let e = Config::parse(path, "[backup]\nmian = \"x:1\"\n").unwrap_err();
        assert!(e.contains("mian"), "{e}");
    }

    #[test]
    fn empty_config_is_the_demo_on_loopback() {
        let c = Config::parse(Path::new("config/visobjd.toml"), "").unwrap();
        assert_eq!(c.scene, Path::new("config/../scenes/demo"));
        assert_eq!(c.osc.udp, "127.0.0.1:8000");
        assert_eq!(c.generate.count, 100);
        assert_eq!(c.output.rate_hz, 44);
    }

    #[test]
    fn shipped_configs_are_valid() {
        for (name, text) in [
            ("visobjd.toml", include_str!("../../config/visobjd.toml")),
            ("booth.toml", include_str!("../../config/booth.toml")),
        ] {
            let c = Config::parse(Path::new(name), text).unwrap();
            c.output.validate(&[1, 2]).unwrap();
        }
    }

    #[test]
    fn unknown_keys_name_the_key_and_line() {
        let e =
            Config::parse(Path::new("c.toml"), "scene = \"x\"\n[osc]\nudpp = \"1\"\n").unwrap_err();
        assert!(e.contains("line 3") && e.contains("udpp"), "{e}");
    }

    #[test]
    fn http_is_off_by_default_and_checked() {
        let c = Config::parse(Path::new("c.toml"), "").unwrap();
        assert_eq!(c.http.listen, "");
        let c =
            Config::parse(Path::new("c.toml"), "[http]\nlisten = \"127.0.0.1:8080\"\n").unwrap();
        assert_eq!(c.http.listen, "127.0.0.1:8080");
        let e = Config::parse(Path::new("c.toml"), "[http]\nlisten = \"8080\"\n").unwrap_err();
        assert!(e.contains("http.listen"), "{e}");
        let dir = std::env::temp_dir().join(format!("visobjd-http-pw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("pw"), "stage left\nignored\n").unwrap();
        let c = Config::parse(&dir.join("c.toml"), "[http]\npassword_file = \"pw\"\n").unwrap();
        assert_eq!(c.http.password, "stage left");
        let e = Config::parse(
            &dir.join("c.toml"),
            "[http]\npassword = \"a\"\npassword_file = \"pw\"\n",
        )
        .unwrap_err();
        assert!(e.contains("not both"), "{e}");
        let e =
            Config::parse(&dir.join("c.toml"), "[http]\npassword_file = \"nope\"\n").unwrap_err();
        assert!(
            e.contains("http.password_file") && e.contains("nope"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
        let e = Config::parse(Path::new("c.toml"), "[http]\nport = 1\n").unwrap_err();
        assert!(e.contains("port"), "{e}");
    }

    #[test]
    fn sacn_input_is_off_by_default_and_checked() {
        let c = Config::parse(Path::new("c.toml"), "").unwrap();
        assert_eq!(c.input.sacn, None);
        let c = Config::parse(
            Path::new("c.toml"),
            "[input.sacn]\nbind = \"127.0.0.1:5568\"\nuniverses = [1, 2]\n",
        )
        .unwrap();
        assert_eq!(c.input.sacn.unwrap().universes, [1, 2]);
        let e = Config::parse(Path::new("c.toml"), "[input.sacn]\nuniverses = []\n").unwrap_err();
        assert!(e.starts_with("c.toml: input.sacn.universes"), "{e}");
        let e = Config::parse(Path::new("c.toml"), "[input.sacn]\nport = 1\n").unwrap_err();
        assert!(e.contains("port"), "{e}");
    }

    #[test]
    fn permits_loopback_by_default_and_the_list_otherwise() {
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        assert!(permits(&[], ip("127.0.0.1")));
        assert!(permits(&[], ip("::1")));
        assert!(permits(&[], ip("::ffff:127.0.0.1")));
        assert!(!permits(&[], ip("10.0.0.5")));
        let list = [Cidr::parse("10.0.0.0/24").unwrap()];
        assert!(permits(&list, ip("10.0.0.5")));
        assert!(!permits(&list, ip("127.0.0.1")));
    }

    #[test]
    fn cidr_blocks_match_v4_v6_and_mapped() {
        let net = Cidr::parse("10.1.0.0/16").unwrap();
        assert!(net.contains("10.1.200.3".parse().unwrap()));
        assert!(!net.contains("10.2.0.1".parse().unwrap()));
        assert!(net.contains("::ffff:10.1.0.9".parse().unwrap()));
        let v6 = Cidr::parse("fd00::/8").unwrap();
        assert!(v6.contains("fd12::1".parse().unwrap()));
        assert!(!v6.contains("fe80::1".parse().unwrap()));
        assert!(
            Cidr::parse("0.0.0.0/0")
                .unwrap()
                .contains("8.8.8.8".parse().unwrap())
        );
        assert!(Cidr::parse("10.0.0.0/33").is_err());
        assert!(Cidr::parse("bogus").is_err());
    }
}
