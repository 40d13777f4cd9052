//! The bridge's configuration file (`--config FILE`, TOML) and the site file it names.
//!
//! Every key is optional; see `systemd/wlnav-fleet.toml` for a commented example.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use shm_ipc::Obstacle;

/// Settings from `--config FILE`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// The map the machine's localization works in: `agvPosition.mapId`, and the only mapId
    /// an order's nodes may have.
    pub map_id: String,
    /// A site file with obstacle circles per mapId (see [`Site`]); none: no obstacles.
    pub site_file: Option<PathBuf>,
    /// Circles given inline, for the map `map_id` (added to the site file's).
    pub obstacles: Vec<Circle>,
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
            site_file: None,
            obstacles: Vec::new(),
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

/// One circle: centre and radius [m] (radius already inflated by the machine's half-width,
/// as on the wire).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Circle {
    /// Centre x [m].
    pub x: f64,
    /// Centre y [m].
    pub y: f64,
    /// Radius [m].
    pub r: f64,
}

/// A site file: obstacle circles per mapId.
///
/// ```toml
/// [maps.site]
/// obstacles = [ { x = 3.0, y = 0.0, r = 0.6 }, { x = 8.0, y = 2.0, r = 1.0 } ]
/// ```
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Site {
    /// mapId → its circles.
    #[serde(default)]
    pub maps: std::collections::BTreeMap<String, SiteMap>,
}

/// The circles of one map.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteMap {
    /// Circles.
    #[serde(default)]
    pub obstacles: Vec<Circle>,
}

impl Config {
    /// Reads and checks a configuration file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
        let config: Self =
            toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
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
        check_circles(&self.obstacles, "obstacles")?;
        Ok(())
    }

    /// The circles of the machine's map: the site file's plus the inline ones.
    pub fn obstacles(&self) -> anyhow::Result<Vec<Obstacle>> {
        let mut circles = self.obstacles.clone();
        if let Some(path) = &self.site_file {
            let site = Site::load(path)?;
            if let Some(map) = site.maps.get(&self.map_id) {
                circles.extend_from_slice(&map.obstacles);
            }
        }
        Ok(circles
            .iter()
            .map(|c| Obstacle::new(c.x, c.y, c.r))
            .collect())
    }
}

impl Site {
    /// Reads and checks a site file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("cannot read site file {}: {e}", path.display()))?;
        let site: Self =
            toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        for (id, map) in &site.maps {
            check_circles(&map.obstacles, &format!("maps.{id}.obstacles"))?;
        }
        Ok(site)
    }
}

fn check_circles(circles: &[Circle], what: &str) -> anyhow::Result<()> {
    for (i, c) in circles.iter().enumerate() {
        anyhow::ensure!(
            c.x.is_finite() && c.y.is_finite() && c.r.is_finite() && c.r > 0.0,
            "{what}[{i}]: centre must be finite and radius > 0"
        );
    }
    Ok(())
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
    fn site_file_and_inline_circles_are_merged() {
        let dir = std::env::temp_dir().join(format!("wlnav-fleet-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let site = dir.join("site.toml");
        std::fs::write(
            &site,
            "[maps.yard]\nobstacles = [{ x = 3.0, y = 0.0, r = 0.6 }]\n[maps.other]\nobstacles = [{ x = 9.0, y = 9.0, r = 1.0 }]\n",
        )
        .unwrap();
        let cfg_path = dir.join("fleet.toml");
        std::fs::write(
            &cfg_path,
            format!(
                "map_id = \"yard\"\nsite_file = {:?}\nobstacles = [{{ x = 1.0, y = 1.0, r = 0.5 }}]\n",
                site
            ),
        )
        .unwrap();
        let cfg = Config::load(&cfg_path).unwrap();
        let obs = cfg.obstacles().unwrap();
        assert_eq!(obs.len(), 2);
        assert!(obs.contains(&Obstacle::new(3.0, 0.0, 0.6)));
        std::fs::write(
            &site,
            "[maps.yard]\nobstacles = [{ x = 3.0, y = 0.0, r = -1.0 }]\n",
        )
        .unwrap();
        assert!(cfg.obstacles().is_err());
        std::fs::write(&cfg_path, "state_interval = 60\n").unwrap();
        assert!(Config::load(&cfg_path).is_err());
        std::fs::write(&cfg_path, "no_such_key = 1\n").unwrap();
        assert!(Config::load(&cfg_path).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
