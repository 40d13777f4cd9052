//! The bridge's configuration file (`--config FILE`, TOML).
//!
//! Every key is optional; see `systemd/wlnav-fleet.toml` for a commented example. The site
//! (its obstacles, and its id, the mapId orders must be on) is the daemon's, not the
//! bridge's: `[site] file` of `wlnavd` (docs/guide/sites.md). The bridge's own site file
//! (`site_file`, `obstacles`) is gone; a configuration that still has those keys is refused
//! saying so.

use std::path::Path;

use serde::Deserialize;

/// Settings from `--config FILE`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// The map orders must be on while the daemon has **no** site (its telemetry's
    /// `site_id` empty): then `agvPosition.mapId` and the only mapId an order's nodes may
    /// have. With a site loaded, the site's id is the map and this key is not used.
    pub map_id: String,
    /// How far [m] the machine may be from a new order's first node (or its
    /// allowedDeviationXY if larger); further is a noRouteError.
    pub first_node_range: f64,
    /// State is published on every event and at least this often [s] (≤ 30).
    pub state_interval: f64,
    /// No telemetry for this long [s] means the daemon is gone (an error in state).
    pub daemon_timeout: f64,
    /// MQTT keep-alive [s].
    pub keep_alive: u64,
    /// MQTT client id; default `wlnav-fleet-<manufacturer>-<serialNumber>`.
    pub client_id: Option<String>,
    /// Topic prefix before `/v2/...`; the specification's `uagv`.
    pub interface_name: String,
    /// What the factsheet and the battery report say about the machine.
    pub machine: MachineInfo,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            map_id: "site".into(),
            first_node_range: 1.0,
            state_interval: 30.0,
            daemon_timeout: 1.5,
            keep_alive: 5,
            client_id: None,
            interface_name: "uagv".into(),
            machine: MachineInfo::default(),
        }
    }
}

/// The machine as the factsheet describes it (defaults: the Avant 635 of DESIGN §2).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MachineInfo {
    /// `typeSpecification.seriesName`.
    pub series_name: String,
    /// Top speed [m/s].
    pub speed_max: f64,
    /// Acceleration limit [m/s²].
    pub acceleration_max: f64,
    /// Deceleration limit [m/s²].
    pub deceleration_max: f64,
    /// Width [m].
    pub width: f64,
    /// Length [m].
    pub length: f64,
    /// Height [m].
    pub height: f64,
    /// Largest load [kg].
    pub max_load_mass: f64,
    /// What `batteryState.batteryCharge` reports. A diesel machine has no traction
    /// battery; the specification requires the field, so the bridge reports this constant
    /// (default 100) with `charging = false` (README, "Fleet link").
    pub battery_charge: f64,
}

impl Default for MachineInfo {
    fn default() -> Self {
        Self {
            series_name: "wlnav articulated loader (Avant 635)".into(),
            speed_max: 1.0,
            acceleration_max: 1.0,
            deceleration_max: 1.0,
            width: 1.3,
            length: 3.0,
            height: 2.1,
            max_load_mass: 1000.0,
            battery_charge: 100.0,
        }
    }
}

/// Keys the bridge's configuration once had, and why they are gone: a configuration with
/// one of them is refused with this text rather than serde's bare "unknown field".
const REMOVED_KEYS: [(&str, &str); 2] = [
    (
        "site_file",
        "the bridge has no site file any more: the site (obstacles, and its id, the mapId \
         orders must be on) is the daemon's, `[site] file` in wlnavd's configuration or \
         `wlnavd --site FILE` (docs/guide/sites.md); remove the key",
    ),
    (
        "obstacles",
        "the bridge sends no obstacle circles any more: put them in the daemon's site \
         (`[site] file` in wlnavd's configuration or `wlnavd --site FILE`, \
         docs/guide/sites.md); remove the key",
    ),
];

impl Config {
    /// Reads and checks a configuration file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }

    /// Parses and checks a configuration's text.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let table: toml::Table = toml::from_str(text)?;
        for (key, why) in REMOVED_KEYS {
            anyhow::ensure!(!table.contains_key(key), "`{key}`: {why}");
        }
        let config: Self = toml::from_str(text)?;
        config.check()?;
        Ok(config)
    }

    /// Checks values that TOML types cannot.
    pub fn check(&self) -> anyhow::Result<()> {
        anyhow::ensure!(!self.map_id.is_empty(), "map_id must not be empty");
        anyhow::ensure!(
            self.first_node_range.is_finite() && self.first_node_range >= 0.0,
            "first_node_range must be a finite distance >= 0"
        );
        anyhow::ensure!(
            self.state_interval > 0.0 && self.state_interval <= 30.0,
            "state_interval must be in (0, 30] s (the specification asks for at least every 30 s)"
        );
        anyhow::ensure!(
            self.daemon_timeout > 0.0 && self.daemon_timeout.is_finite(),
            "daemon_timeout must be > 0"
        );
        anyhow::ensure!(self.keep_alive >= 1, "keep_alive must be >= 1 s");
        anyhow::ensure!(
            !self.interface_name.is_empty() && !self.interface_name.contains(['/', '+', '#']),
            "interface_name must be one topic level"
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_example_is_the_defaults() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../systemd/wlnav-fleet.toml");
        assert_eq!(Config::load(&path).unwrap(), Config::default());
    }

    #[test]
    fn bad_and_unknown_keys_are_refused() {
        assert_eq!(Config::parse("map_id = \"yard\"\n").unwrap().map_id, "yard");
        assert!(Config::parse("state_interval = 60\n").is_err());
        assert!(Config::parse("map_id = \"\"\n").is_err());
        let e = Config::parse("no_such_key = 1\n").unwrap_err().to_string();
        assert!(e.contains("no_such_key"), "{e}");
        let e = Config::parse("[machine]\nwheels = 4\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("wheels"), "{e}");
    }

    #[test]
    fn the_removed_site_keys_say_where_the_site_is_now() {
        for text in [
            "site_file = \"/etc/wlnav/site.toml\"\n",
            "obstacles = [{ x = 1.0, y = 1.0, r = 0.5 }]\n",
        ] {
            let e = Config::parse(text).unwrap_err().to_string();
            let key = text.split(' ').next().unwrap();
            assert!(
                e.contains(&format!("`{key}`"))
                    && e.contains("[site] file")
                    && e.contains("--site"),
                "{e}"
            );
        }
        // Through a file: the path is named too.
        let dir = std::env::temp_dir().join(format!("wlnav-fleet-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("fleet.toml");
        std::fs::write(&path, "map_id = \"yard\"\nsite_file = \"site.toml\"\n").unwrap();
        let e = Config::load(&path).unwrap_err().to_string();
        assert!(e.contains("fleet.toml") && e.contains("[site] file"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
