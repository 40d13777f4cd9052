//! # wlnav-fleet: VDA 5050 over MQTT for wlnavd
//!
//! A site's fleet manager (the VDA 5050 "master control") drives the loaders through an
//! MQTT broker; `wlnav-fleet` is one loader's end of it (DESIGN §16). It speaks VDA 5050
//! **2.0.0** on `uagv/v2/<manufacturer>/<serialNumber>/…` and talks to `wlnavd` over the
//! shared-memory wire of [`shm_ipc`] (and nothing else of the project).
//!
//! | topic | direction | QoS | retained |
//! |---|---|---|---|
//! | `order` | master → vehicle | 0 | no |
//! | `instantActions` | master → vehicle | 0 | no |
//! | `state` | vehicle → master | 0 | no |
//! | `visualization` | vehicle → master | 0 | no |
//! | `connection` | vehicle → master | 1 | yes (last will `CONNECTIONBROKEN`) |
//! | `factsheet` | vehicle → master | 0 | yes |
//!
//! The parts:
//!
//! * [`vda`]: the messages, the project's own serde types, checked against the official
//!   JSON schemas in `fleet/schemas/` by the tests.
//! * [`order`]: pure order logic: validation, the accept / update / reject flow, stitching,
//!   node traversal, the map orders must be on (the daemon's site, [`order::VehicleMap`]).
//! * [`vehicle`]: the vehicle's state machine: events in, effects out (requests for the
//!   daemon, state to publish); no I/O.
//! * [`bridge`]: the thin I/O layer (rumqttc, the daemon thread).
//! * [`config`]: the configuration file. The site (obstacles, map id) is the daemon's
//!   (DESIGN §17): goals go without circles, and an order's nodes must be on the daemon's
//!   site (`nodePosition.mapId` = the site's id; the configured `map_id` while the daemon
//!   has none).
//!
//! How an order becomes goals: the released nodes are driven one at a time, each as a
//! goal of the daemon. An intermediate node with `allowedDeviationXY` > 0 (and, if it has a
//! `theta`, `allowedDeviationTheta` > 0) is passed without stopping: as soon as the machine
//! is within the deviation, the next node's goal replaces it. A node with zero deviation,
//! and always the last released node, is traversed when the daemon reports the goal
//! `succeeded` (at rest within its reach tolerance). Horizon nodes are never sent.

pub mod bridge;
pub mod config;
pub mod factsheet;
pub mod order;
pub mod vda;
pub mod vehicle;
