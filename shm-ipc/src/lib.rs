//! # shm-ipc: how programs talk to `wlnavd`
//!
//! Goals, poses, live obstacles and telemetry travel over [iceoryx2](https://docs.rs/iceoryx2/0.10) shared
//! memory (no broker, zero-copy, C/C++/Python bindings). This crate holds the wire types,
//! the service names, a goal validator the daemon uses, and a small client library:
//!
//! * [`DaemonEndpoint`]: the daemon's side (serve goal requests, publish [`Telemetry`],
//!   read [`PoseEstimate`]s and [`LiveObstacleSet`]s, wait on events).
//! * [`Client`]: everyone else (send a goal and get accept/reject with a reason, cancel,
//!   stop, resume, publish poses, [`Client::subscribe_telemetry`]). It only *opens* the
//!   services the daemon created ([`IpcError::NotServed`] without a daemon;
//!   [`Client::connect`] waits for one).
//! * [`StopClient`]: the reserved stop path; gets through when every goal client slot is
//!   taken, falls back to the goal service when every stop slot is, and sends without a
//!   notification when no notifier is free ([`StopClient::stop_report`] says which way it
//!   went). A stop on it latches like one on the goal service.
//! * [`GoalValidator`]: finite numbers, inside the workspace, heading not absurd, ≤ 8
//!   obstacles with positive radius; rejections carry a [`RejectReason`]; accepted headings
//!   are normalised to (−π, π]. (The footprint checks against the obstacles need the
//!   machine and are the daemon's.)
//! * [`ObstaclePublisher`]: the one publisher of live obstacles, for a perception stack
//!   (DESIGN §18); [`LiveObstacleValidator`]: the rules the daemon checks every
//!   [`LiveObstacleSet`] against (a set with one bad obstacle is rejected whole, with a
//!   [`LiveSetRejection`] naming the rule and the obstacle).
//!
//! The `wlnav` command-line client is its own crate (`wlnav-cli`), built on this one.
//!
//! ```no_run
//! use shm_ipc::{Client, IpcConfig, Pose2};
//! use std::time::Duration;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let client = Client::connect(&IpcConfig::default(), Duration::from_secs(5))?;
//! let reply = client.set_goal(Pose2::new(4.5, 0.0, 0.0), &[], Duration::from_secs(1))?;
//! if !reply.is_accepted() {
//!     eprintln!("rejected: {}", reply.reason_text());
//! }
//! # Ok(()) }
//! ```
//!
//! ## Services
//!
//! With prefix `P` (default `wlnav`, see [`IpcConfig`]; different prefixes never meet, which
//! is how parallel tests and several daemons on one host stay apart):
//!
//! | service name | pattern | payload | paired event service (same name) |
//! |---|---|---|---|
//! | `P/v2/goal` | request-response | [`GoalRequest`] → [`GoalReply`] | event id 1 after a request, 2 after a reply |
//! | `P/v2/stop` | request-response | [`GoalRequest`] (kind 3 only) → [`GoalReply`] | event id 5 after a request, 6 after a reply |
//! | `P/v2/pose` | publish-subscribe | [`PoseEstimate`] | event id 3 after each sample |
//! | `P/v2/telemetry` | publish-subscribe | [`Telemetry`] (one per control tick) | event id 4 after each sample |
//! | `P/v2/obstacles` | publish-subscribe | [`LiveObstacleSet`] (perception → daemon, one publisher) | event id 7 after each set |
//!
//! ## What a peer must know
//!
//! * **iceoryx2 version and flavour.** Use iceoryx2 **0.10.0** exactly (the shared-memory
//!   layout of iceoryx2's own management structures changes between releases; 0.10.x
//!   patch releases that keep it are compatible, a different minor version is not), with
//!   the default configuration (no `iceoryx2.toml`, or one with the default root path and
//!   prefixes). This crate uses the `ipc_threadsafe` service flavour; it is the same on
//!   the wire as the plain `ipc` flavour (`iox2.ServiceType.Ipc` in Python,
//!   `ServiceType::Ipc` in C/C++), which foreign peers use.
//! * **The daemon creates the services; peers only open them** (`open()`, never
//!   `open_or_create()`). A peer that creates a service before the daemon starts makes the
//!   daemon refuse to start, with a message naming the service and the processes attached
//!   to it. When opening, set no quality-of-service values (or values not above the
//!   settings below).
//! * **Replies and wake-ups.** After sending a request, notify the paired event service
//!   with event id 1 (goal) or 5 (stop); the daemon notifies id 2 / 6 after each reply, so
//!   a client sleeps on a listener of the same event service and then reads its pending
//!   response. The daemon's request loop also wakes every **50 ms** by itself, so a
//!   request sent without a notification is answered within about 50 ms; and whatever
//!   wakes it (a notification on the goal or the stop event service, or the period), it
//!   serves the stop service first, then the goal service. Telemetry is
//!   published once per control tick (5 Hz) followed by event id 4. A localization that
//!   publishes poses should notify id 3 (the control loop reads poses once per tick
//!   anyway).
//! * **The newest goal wins.** Each accepted set-goal replaces the previous goal at the
//!   next tick; a rejected one leaves it in place. Cancel (2), stop (3) and resume (4)
//!   are always accepted. A stop latches: set-goals are rejected (not ready) until a
//!   resume (4) on `P/v2/goal`. A stop sent on `P/v2/stop` is handled (and latches) like
//!   one on `P/v2/goal`.
//! * **Goals.** Workspace bounds are **inclusive** (a goal exactly on the edge is
//!   accepted), as is an obstacle boundary (distance = r). Headings are **normalised to
//!   (−π, π]** on acceptance (telemetry reports the normalised value); a finite heading
//!   with |heading| > 1e4 rad, or an obstacle number beyond 1e6 m, is rejected as absurd.
//!   Reject reasons are UTF-8, at most 128 bytes, shortened at a word boundary with `…`.
//! * **One pose source.** `P/v2/pose` admits a **single publisher**: a second one is
//!   refused ([`IpcError::PoseSourceTaken`]), so nobody can mix samples into the
//!   localization's. The daemon reads every sample and rejects (and counts) samples
//!   stamped more than 50 ms in the future of its `CLOCK_MONOTONIC`, outside the
//!   workspace (plus a margin), or implying a jump the machine cannot make since the last
//!   accepted sample; a run of rejects is a pose fault (controlled stop, fault bit
//!   [`fault_flags::POSE_REJECTED`]). Samples without the valid flag are ignored; age is
//!   judged on accepted samples only.
//! * **One obstacle source.** `P/v2/obstacles` admits a **single publisher**, for any
//!   perception stack: a second one is refused ([`IpcError::ObstacleSourceTaken`], naming
//!   the holder). Each [`LiveObstacleSet`] replaces the previous one as a whole; publish
//!   the complete set at perception's rate (an empty set when nothing is seen) and notify
//!   id 7. The daemon checks every set with [`LiveObstacleValidator`] and drops a set that
//!   fails, whole; freshness is judged on the set's `timestamp_ns`.
//! * **The stop path.** `P/v2/stop` has its own 16 client slots; the `wlnav` CLI and
//!   [`StopClient`] hold a port there only while a stop is in flight, so a process that
//!   holds all 32 goal client slots cannot keep a stop out. One that holds all 16 stop
//!   slots cannot either: the stop then goes to `P/v2/goal` as kind 3. See "The stop
//!   service" below.
//!
//! iceoryx2 has no async API, so every data service has an event service of the **same
//! name** (iceoryx2 distinguishes services by name and messaging pattern). A sender
//! notifies after sending; a receiver sleeps on its listener (or on the listener's file
//! descriptor, e.g. with tokio `AsyncFd`) and then reads the data service until empty.
//! Nobody busy-polls. A foreign peer that sends must notify likewise, or the daemon only
//! sees its message at its next periodic wake-up.
//!
//! Service settings the daemon creates the services with (a peer opens without
//! requirements, or with values not above these): goal: max 1 server, 32 clients, 16
//! active requests per client, 64 nodes, safe overflow on; stop: max 1 server, 16
//! clients, 2 active requests per client, 64 nodes; pose: **1 publisher**, 8 subscribers;
//! telemetry: 2 publishers, 16 subscribers; both: subscriber buffer 16, history 1, safe
//! overflow on, 64 nodes; obstacles: **1 publisher**, 4 subscribers, subscriber buffer
//! **1**, history 1, safe overflow on, 64 nodes; events: 64 listeners, 64 notifiers, 64
//! nodes. User headers are
//! empty (`()`, size 0). Each payload is registered under the type name given below (the
//! `type_name` iceoryx2 compares when opening; in C++ set `IOX2_TYPE_NAME` to it; in
//! Python see "Type names from Python" below).
//!
//! ## Answers for client writers
//!
//! ### Type names from Python
//!
//! iceoryx2 refuses to open a service whose payload type name differs from the
//! creator's. In Python (iceoryx2's `iceoryx2` package, 0.10.0) each payload is a
//! `ctypes.Structure` with the fields of the tables below, in that order, and a static
//! method `type_name()` returning the name in the tables, as iceoryx2's own
//! cross-language Python examples do:
//!
//! ```python
//! import ctypes
//! class Pose2(ctypes.Structure):
//!     _fields_ = [("x", ctypes.c_double), ("y", ctypes.c_double), ("heading", ctypes.c_double)]
//!     @staticmethod
//!     def type_name() -> str:
//!         return "wlnav::v2::Pose2"
//! # GoalRequest: request_id c_uint64, kind c_uint32, obstacle_count c_uint32,
//! # goal Pose2, obstacles Obstacle * 8; type_name() -> "wlnav::v2::GoalRequest"
//! ```
//!
//! Nested structs need their own `type_name()` too. `ctypes` aligns `c_double` and
//! `c_uint64` to 8 bytes like the C declaration below, so `ctypes.sizeof` must give the
//! sizes in the tables (232 for `GoalRequest`, 152 for `GoalReply`, …); check that first.
//! Open with `iox2.ServiceType.Ipc`; the request-response service is
//! `request_response(GoalRequest, GoalReply)` with no user header.
//!
//! ### Goals: workspace, footprint, and which reject code wins
//!
//! * **Workspace**: goals must lie in the daemon's `[ipc] workspace`, default x and y in
//!   [−50, 50] m, bounds inclusive. The daemon logs the configured workspace at start-up
//!   ("goal checks: …").
//! * **Footprint** (`goal-in-collision`, `machine-in-collision`): both axle points
//!   against every obstacle, a point exactly on a circle counting as outside. At the
//!   goal (β = 0) the front axle is the goal's (x, y) and the rear axle lies
//!   L_f + L_r behind it along the heading: (x − (L_f + L_r) cos θ, y − (L_f + L_r) sin θ).
//!   The current footprint is the machine's state in telemetry: front axle
//!   (`x_f`, `y_f`), rear axle at (x_f − L_f cos θ_f − L_r cos(θ_f − β),
//!   y_f − L_f sin θ_f − L_r sin(θ_f − β)). The axle lengths are the daemon's `[machine]`
//!   `l_f` and `l_r` (the Avant 635 of the default config: 0.6 m and 0.6 m; other
//!   machines take theirs from their weights' metadata). They are not on the wire: the
//!   daemon writes them to its start-up log ("goal checks: …, L_f … m, L_r … m") and
//!   `wlnavd --print-config` lists them. A client that cannot know them can send the
//!   goal and read the reply: the check costs nothing and the text names the axle and
//!   the obstacle.
//! * **Which code wins**: the checks run in this order and the first that fails is
//!   answered: unknown kind (6) → more than 8 obstacles (3) → a non-finite goal number,
//!   x, y, then heading (1) → a non-finite obstacle centre, by index (1) → goal outside
//!   the workspace (2) → |heading| > 1e4 rad (2) → per obstacle, by index: radius not
//!   positive and finite (4; a NaN radius is 4, not 1), then |x|, |y| or r beyond 1e6 m
//!   (4) → not ready (7: shutting down, stopped by an operator, or a blocking fault) →
//!   goal in collision (5, the obstacle the footprint enters deepest) → machine in
//!   collision (9). Cancel, stop and resume are never rejected on the goal service.
//!
//! ### The pose gate's margins
//!
//! With the default `[loop]` and `[machine]` settings a pose sample is rejected (and
//! counted) when it is stamped more than `pose_max_future` = 0.05 s ahead of the
//! daemon's `CLOCK_MONOTONIC`; when it lies outside the workspace grown by
//! `pose_workspace_margin` = 10 m on every side; when it is farther from the last accepted
//! pose than v_max · (1 + `plausibility_margin`) · Δt + `pose_jump_tolerance` = 1.0 m/s ·
//! 1.2 · Δt + 0.5 m (Δt the time between the two stamps); or when its heading differs by
//! more than the model's largest yaw rate · 1.2 · Δt + `pose_heading_tolerance` = 0.3 rad.
//! `pose_reject_stop` = 5 rejects in a row are a pose fault (controlled stop); an
//! accepted pose older than `pose_timeout` = 0.5 s is stale (controlled stop).
//!
//! ### Overflow, per direction
//!
//! * **Requests, client → daemon** (goal and stop services): iceoryx2's defaults, safe
//!   overflow on; a client may have 16 requests in flight on the goal service (2 on the
//!   stop service); a further send fails on the client side
//!   (`ExceedsMaxActiveRequests`) until a reply is read or a pending request dropped.
//!   A request the daemon drops unanswered reaches the client as
//!   [`ClientError::Dropped`].
//! * **Replies, daemon → client**: one reply per request, response buffer 2 (iceoryx2's
//!   default), safe overflow on: nothing is lost, a reply waits until read.
//! * **Poses, localization → daemon**: the daemon's subscriber buffer holds 16 samples,
//!   safe overflow on (the oldest unread sample is overwritten; the publisher never
//!   blocks); the daemon reads them all every tick.
//! * **Live obstacles, perception → daemon**: the daemon's subscriber buffer holds **one**
//!   set, safe overflow on: a new set overwrites an unread one, so the daemon always reads
//!   the newest, the publisher never blocks, and a flood grows nothing (the shared memory
//!   is sized once, at creation). Only the newest set matters: each replaces the last.
//! * **Telemetry, daemon → subscribers**: 16 samples per subscriber, safe overflow on
//!   (a slow reader loses the oldest, `tick` and `outcome_seq` show the gap); history 1
//!   (a new subscriber gets the latest sample at once).
//! * **Events**: notifications are wake-ups only and never queue data; several
//!   notifications before a wait coalesce.
//!
//! ### Slots, nodes and request ids
//!
//! * **Goal service**: 32 client slots. `wlnavd` itself holds none (it holds the one
//!   server); `wlnavd --sim` takes one for its simulated localization (a [`Client`] that
//!   publishes poses), leaving **31**. Every [`Client`] (and `wlnav goal`, `cancel`,
//!   `resume`, `watch`, `record`, while running) holds one for its lifetime.
//! * **Nodes**: each process that opens a service is one of its 64 nodes (a [`Client`]
//!   opens all five data services and their event services; a [`StopClient`] only the
//!   stop service, and the goal service when it falls back).
//! * **Event ports**: 64 notifiers and 64 listeners per event service. The daemon holds
//!   one notifier and one listener on the goal and on the stop event service, one
//!   listener on the pose and on the obstacle event service and one notifier on the
//!   telemetry event service; a [`Client`] one notifier and one listener on the goal
//!   event service, one notifier on the pose event service once it publishes, and one
//!   listener per telemetry subscription; an [`ObstaclePublisher`] one notifier on the
//!   obstacle event service.
//! * **Request ids** need not be unique across clients for the replies: iceoryx2 routes
//!   each reply to the client connection that sent the request. They should be unique
//!   for telemetry: `goal_request_id` and `outcome_request_id` are how a client finds its
//!   goal there. This library starts each [`Client`]'s ids at `CLOCK_MONOTONIC` in
//!   nanoseconds and counts up, and [`StopClient::stop`] uses the clock; do the same
//!   (Python: `time.monotonic_ns()`) and never send 0 (telemetry's "none").
//!
//! ### The stop service
//!
//! `P/v2/stop` takes **stop requests (kind 3) only**. Any other kind, resume included,
//! is answered `accepted = 0`, code 6 (unknown kind), "the stop service takes only stop
//! requests (kind 3), got kind N", and changes nothing; send resume on `P/v2/goal`. Its
//! limits: 1 server (the daemon), **16 client slots**, 2 requests in flight per client,
//! 64 nodes; its event service: **64 notifiers and 64 listeners**, of which the daemon
//! holds one each (63 free). [`StopClient`] takes a client, a notifier and a listener
//! per stop and releases them with the reply. When another process holds:
//!
//! * every stop client slot (or the stop service's nodes): the stop goes on `P/v2/goal`
//!   as kind 3 (handled and latched the same way);
//! * every notifier of the stop event service: the request goes anyway and the daemon is
//!   woken through the goal event service (id 5); with no notifier free there either, it
//!   goes without a notification and the daemon's 50 ms pass answers it;
//! * every listener: the reply is polled for every 2 ms.
//!
//! A peer in another language should do the same: a stop needs only a client port; a
//! notifier and a listener are optional. Every "slots taken" error
//! ([`IpcError::PortsExhausted`], [`IpcError::AlreadyServed`],
//! [`IpcError::PoseSourceTaken`], [`IpcError::ObstacleSourceTaken`]) names the processes
//! holding the ports (node name, pid,
//! executable), or says that the holder could not be found.
//!
//! ## Payload layout (wire format v2)
//!
//! All payloads are `#[repr(C)]`, little-endian (the host's; shared memory never leaves the
//! host), 8-byte aligned, without pointers and **without implicit padding** (spare bytes
//! are explicit `_reserved` fields, written as zero). `f64` is IEEE-754 binary64, angles are
//! radians (counter-clockwise, world frame), lengths metres, times nanoseconds of
//! `CLOCK_MONOTONIC` (see [`monotonic_now_ns`]). Enumerations and flags are `u32`; unknown
//! codes are rejected or ignored, never trusted. Sizes and offsets are checked at compile
//! time in `msg.rs`.
//!
//! Shared structs:
//!
//! | struct (type name) | size | fields (offset: type name \[unit\]) |
//! |---|---|---|
//! | `Pose2` (`wlnav::v2::Pose2`) | 24 | 0: f64 x \[m\]; 8: f64 y \[m\]; 16: f64 heading \[rad\] |
//! | `Obstacle` (`wlnav::v2::Obstacle`) | 24 | 0: f64 x \[m\]; 8: f64 y \[m\]; 16: f64 r \[m\] |
//! | `MachineState` (`wlnav::v2::MachineState`) | 48 | 0: f64 x_f \[m\]; 8: f64 y_f \[m\]; 16: f64 theta_f \[rad\]; 24: f64 beta \[rad\]; 32: f64 beta_dot \[rad/s\]; 40: f64 v_f \[m/s\] |
//! | `Command` (`wlnav::v2::Command`) | 16 | 0: f64 beta_dot \[rad/s\]; 8: f64 v \[m/s\] |
//!
//! [`GoalRequest`] (`wlnav::v2::GoalRequest`), 232 bytes:
//!
//! | offset | type | field | meaning |
//! |---|---|---|---|
//! | 0 | u64 | request_id | chosen by the client, echoed in the reply |
//! | 8 | u32 | kind | 1 set goal, 2 cancel, 3 stop (latches), 4 resume ([`GoalKind`]); the stop service takes 3 only |
//! | 12 | u32 | obstacle_count | 0..=8 valid entries in `obstacles` |
//! | 16 | Pose2 | goal | front-axle goal pose (set goal only) |
//! | 40 | Obstacle\[8\] | obstacles | circular obstacles, radius already inflated; unused entries zero |
//!
//! [`GoalReply`] (`wlnav::v2::GoalReply`), 152 bytes:
//!
//! | offset | type | field | meaning |
//! |---|---|---|---|
//! | 0 | u64 | request_id | the request answered |
//! | 8 | u32 | accepted | 1 accepted, 0 rejected |
//! | 12 | u32 | reason_code | [`RejectCode`]: 0 none, 1 non-finite, 2 out of workspace (or absurd heading), 3 too many obstacles, 4 bad obstacle (radius, or a number beyond 1e6 m), 5 goal-in-collision, 6 unknown kind, 7 not ready, 8 other, 9 machine-in-collision |
//! | 16 | u32 | reason_len | valid bytes in `reason` (≤ 128; a longer text is shortened at a word boundary and ends with `…`) |
//! | 20 | u32 | _reserved | 0 |
//! | 24 | u8\[128\] | reason | UTF-8 text, zero-filled after `reason_len` |
//!
//! [`PoseEstimate`] (`wlnav::v2::PoseEstimate`), 112 bytes:
//!
//! | offset | type | field | meaning |
//! |---|---|---|---|
//! | 0 | u64 | timestamp_ns | measurement time, `CLOCK_MONOTONIC` \[ns\] |
//! | 8 | u32 | sequence | publisher's counter (wraps) |
//! | 12 | u32 | flags | bit 0 valid, bit 1 covariance valid ([`pose_flags`]) |
//! | 16 | f64 | x | front-axle centre \[m\] |
//! | 24 | f64 | y | front-axle centre \[m\] |
//! | 32 | f64 | heading | front-body heading θ_f \[rad\] |
//! | 40 | f64\[9\] | covariance | row-major 3×3 of (x, y, heading) \[m², m·rad, rad²\] |
//!
//! [`Telemetry`] (`wlnav::v2::Telemetry`), 2816 bytes:
//!
//! | offset | type | field | meaning |
//! |---|---|---|---|
//! | 0 | u64 | tick | control tick counter |
//! | 8 | u64 | timestamp_ns | tick start, `CLOCK_MONOTONIC` \[ns\] |
//! | 16 | u64 | goal_request_id | request id of the active goal, 0 if none |
//! | 24 | u32 | mode | [`Mode`]: 0 startup, 1 idle, 2 tracking, 3 reached, 4 stopping, 5 fault |
//! | 28 | u32 | fault_flags | [`fault_flags`] bits |
//! | 32 | u32 | goal_active | 1 if `goal` is valid |
//! | 36 | u32 | trajectory_len | valid entries in `trajectory` (≤ 41) |
//! | 40 | u32 | qp_iterations | QP iterations this tick |
//! | 44 | u32 | sqp_iterations | SQP iterations this tick |
//! | 48 | f64 | solve_time_us | solve wall time \[µs\] |
//! | 56 | f64 | cost | optimal cost |
//! | 64 | f64 | pose_error_xy | position error to the goal \[m\] |
//! | 72 | f64 | pose_error_heading | wrapped heading error \[rad\] |
//! | 80 | MachineState | state | x = \[x_f, y_f, θ_f, β, β̇, v_f\] |
//! | 128 | Pose2 | goal | active goal |
//! | 152 | Command | command | (β̇_cmd, v_cmd) sent this tick |
//! | 168 | MachineState\[41\] | trajectory | planned x₀..x_N |
//! | 2136 | u64 | outcome_request_id | request id of the goal that ended this tick, 0 if none |
//! | 2144 | u32 | outcome | [`GoalOutcome`]: 0 none, 1 succeeded, 2 cancelled, 3 preempted, 4 aborted |
//! | 2148 | u32 | abort_reason | [`AbortReason`] (aborted only, else 0): 1 no-progress, 2 no-route, 3 goal-in-collision, 4 fault, 5 shutdown |
//! | 2152 | u32 | outcome_seq | 1, 2, … per ended goal since daemon start; 0 if none |
//! | 2156 | u32 | outcome_text_len | valid bytes in `outcome_text` (≤ 128) |
//! | 2160 | u8\[128\] | outcome_text | UTF-8 reason, zero-filled after `outcome_text_len` |
//! | 2288 | u32 | subgoal_active | 1 if `subgoal` is valid (global layer) |
//! | 2292 | u32 | route_len | valid entries in `route` (≤ 16) |
//! | 2296 | Pose2 | subgoal | the intermediate goal the MPC drives to |
//! | 2320 | Pose2\[16\] | route | global route towards the goal, rest zero |
//! | 2704 | f64 | plan_time_us | wall time of the last route plan (planner thread) \[µs\] |
//! | 2712 | f64 | route_age_s | age of the route followed when it arrived \[s\] |
//! | 2720 | u32 | at_rest | 1: \|v_f\| and \|β̇\| below `loop.rest_speed` (the one "at rest") |
//! | 2724 | u32 | live_id | the live obstacle the command comes nearest to, with `live-near` (DESIGN §18; else 0) |
//! | 2728 | u64 | site_version | the loaded site's version (DESIGN §17; 0: no site) |
//! | 2736 | u64 | site_hash | the site file's content hash (FNV-1a 64; 0: no site) |
//! | 2744 | u32 | site_id_len | valid bytes in `site_id` (≤ 64) |
//! | 2748 | u32 | _reserved_site | zero |
//! | 2752 | u8\[64\] | site_id | the loaded site's id, UTF-8, zero-filled |
//!
//! [`LiveObstacleSet`] (`wlnav::v2::LiveObstacleSet`), 24 592 bytes (DESIGN §18):
//!
//! | offset | type | field | meaning |
//! |---|---|---|---|
//! | 0 | u64 | timestamp_ns | the set's measurement time, `CLOCK_MONOTONIC` \[ns\]: freshness is judged on it |
//! | 8 | u32 | sequence | publisher's counter (wraps) |
//! | 12 | u32 | count | 0..=128 valid entries in `obstacles` (more: the set is rejected) |
//! | 16 | LiveObstacle\[128\] | obstacles | the current live obstacles; unused entries zero |
//!
//! [`LiveObstacle`] (`wlnav::v2::LiveObstacle`), 192 bytes, at 16 + 192 i in the set:
//!
//! | offset | type | field | meaning |
//! |---|---|---|---|
//! | 0 | u32 | id | perception's track id, unique in the set |
//! | 4 | u32 | shape | [`ObstacleShape`]: 0 circle, 1 convex polygon |
//! | 8 | u32 | class | [`ObstacleClass`]: 0 unknown, 1 person, 2 vehicle, 3 machine, 4 static/other |
//! | 12 | u32 | vertex_count | polygon: 3..=8 valid entries in `vertices`; circle: 0 |
//! | 16 | u64 | timestamp_ns | when this obstacle was observed, `CLOCK_MONOTONIC` \[ns\] (≤ the set's + 0.05 s) |
//! | 24 | f64 | x | circle centre \[m\], world frame (polygon: ignored, 0) |
//! | 32 | f64 | y | circle centre \[m\] (polygon: ignored, 0) |
//! | 40 | f64 | radius | circle's **physical** radius \[m\], not inflated by the machine (polygon: ignored, 0) |
//! | 48 | f64 | vx | velocity \[m/s\], world frame |
//! | 56 | f64 | vy | velocity \[m/s\], world frame |
//! | 64 | f64\[8\]\[2\] | vertices | polygon (x, y) \[m\], world frame, in order around it (either winding); vertex k at 64 + 16 k |
//!
//! The rules a set must pass, and their defaults, are [`LiveObstacleValidator`]'s.
//!
//! ## Goal lifecycle
//!
//! A set-goal request is answered at once: accepted, or rejected with a [`RejectCode`] and
//! a text. Besides the request's own checks ([`GoalValidator`]) the daemon rejects a goal
//! whose footprint (both axle points at the goal pose with β = 0) lies inside an obstacle
//! (`goal-in-collision`), a request one of whose obstacles contains the machine's current
//! footprint (`machine-in-collision`), and any goal while it is not ready (`not-ready`:
//! starting, faulted, shutting down, or stopped by an operator).
//!
//! The newest accepted goal wins. **Every accepted goal ends in exactly one outcome**,
//! reported in exactly one telemetry sample: `outcome`, `abort_reason`,
//! `outcome_request_id` (the ended goal's id, not the active one's) and `outcome_text`.
//! `succeeded` when reached (the machine then holds, mode `reached`); `cancelled` by a
//! cancel or stop request; `preempted` by a newer goal (also a goal superseded before the
//! daemon's next tick took it up); `aborted` with a reason: `no-progress` (the error to the
//! goal did not shrink by 0.1 for `loop.progress_timeout`, default 10 s), `no-route`,
//! `goal-in-collision`, `fault` (the fault is named), `shutdown`. After every outcome but
//! `succeeded` the goal is dropped and the machine brought to rest (controlled stop).
//!
//! A tick carries at most one outcome. Goals that end together (a flood of goals within
//! one tick) are reported on consecutive ticks in the order they ended; up to 32 wait, and
//! beyond that the oldest are dropped. `outcome_seq` numbers ended goals consecutively, so
//! a gap tells a reader it missed one (its subscriber buffer of 16 samples overflowed, or
//! the daemon dropped it). A client waiting for its goal matches `outcome_request_id`.
//!
//! **Operator stop latches** (DESIGN §11): after a stop request (kind 3) every set-goal is
//! rejected with `not-ready` ("stopped by an operator …") and telemetry shows fault bit
//! `STOP_REQUESTED`, until a resume request (kind 4). Cancel, stop and resume are always
//! accepted.
//!
//! A C declaration that matches byte for byte:
//!
//! ```c
//! typedef struct { double x, y, heading; } wlnav_pose2;              /* 24 */
//! typedef struct { double x, y, r; } wlnav_obstacle;                 /* 24 */
//! typedef struct { double x_f, y_f, theta_f, beta, beta_dot, v_f; } wlnav_state; /* 48 */
//! typedef struct { double beta_dot, v; } wlnav_command;              /* 16 */
//! typedef struct { uint64_t request_id; uint32_t kind, obstacle_count;
//!                  wlnav_pose2 goal; wlnav_obstacle obstacles[8]; } wlnav_goal_request; /* 232 */
//! typedef struct { uint64_t request_id; uint32_t accepted, reason_code, reason_len, reserved;
//!                  uint8_t reason[128]; } wlnav_goal_reply;          /* 152 */
//! typedef struct { uint64_t timestamp_ns; uint32_t sequence, flags;
//!                  double x, y, heading, covariance[9]; } wlnav_pose_estimate; /* 112 */
//! typedef struct { uint64_t tick, timestamp_ns, goal_request_id;
//!                  uint32_t mode, fault_flags, goal_active, trajectory_len, qp_iterations, sqp_iterations;
//!                  double solve_time_us, cost, pose_error_xy, pose_error_heading;
//!                  wlnav_state state; wlnav_pose2 goal; wlnav_command command;
//!                  wlnav_state trajectory[41];
//!                  uint64_t outcome_request_id;
//!                  uint32_t outcome, abort_reason, outcome_seq, outcome_text_len;
//!                  uint8_t outcome_text[128];
//!                  uint32_t subgoal_active, route_len;
//!                  wlnav_pose2 subgoal, route[16];
//!                  double plan_time_us, route_age_s;
//!                  uint32_t at_rest, live_id;
//!                  uint64_t site_version, site_hash;
//!                  uint32_t site_id_len, _reserved_site;
//!                  uint8_t site_id[64]; } wlnav_telemetry; /* 2816 */
//! typedef struct { uint32_t id, shape, class_, vertex_count; uint64_t timestamp_ns;
//!                  double x, y, radius, vx, vy, vertices[8][2]; } wlnav_live_obstacle; /* 192 */
//! typedef struct { uint64_t timestamp_ns; uint32_t sequence, count;
//!                  wlnav_live_obstacle obstacles[128]; } wlnav_live_obstacle_set; /* 24592 */
//! ```
//!
//! ## Start-up clean-up
//!
//! iceoryx2 has no central daemon: a process that dies leaves its node's files under
//! `/dev/shm/iox2_*` and `/tmp/iceoryx2`. Both endpoints list the nodes on start
//! (`Node::list`) and remove dead ones ([`IpcConfig::cleanup_stale_nodes`], on by default),
//! so a restarted daemon finds its goal server slot free.

#![warn(missing_docs)]

mod config;
mod endpoint;
mod error;
mod holders;
mod msg;
mod validate;
mod validate_live;

/// The iceoryx2 version this crate is built against, for callers that need more of it (e.g.
/// `iceoryx2::set_log_level` to silence its "no config file" warning in a CLI).
pub use iceoryx2;

pub use config::{
    validate_prefix, IpcConfig, ServiceNames, API_VERSION, DEFAULT_PREFIX, MAX_PREFIX_LEN,
};
pub use endpoint::{
    cleanup_stale_nodes, event_ids, qos, CleanupReport, Client, DaemonEndpoint, IncomingGoal,
    IpcService, ObstaclePublisher, PendingGoal, StopClient, StopPath, StopReport,
    TelemetrySubscriber, Wakeup,
};
pub use error::{BoxedSource, ClientError, IpcError};
pub use msg::{
    fault_flags, pose_flags, AbortReason, Command, GoalKind, GoalOutcome, GoalReply, GoalRequest,
    LiveObstacle, LiveObstacleError, LiveObstacleSet, MachineState, Mode, Obstacle, ObstacleClass,
    ObstacleShape, Pose2, PoseEstimate, RejectCode, Telemetry, MAX_LIVE_OBSTACLES, MAX_OBSTACLES,
    MAX_POLYGON_VERTICES, MAX_ROUTE, MAX_TRAJECTORY, REASON_TEXT_CAPACITY, SITE_ID_CAPACITY,
};
pub use validate::{
    heapless_obstacles, normalize_angle, GoalValidator, Num, RejectReason, ValidRequest, Workspace,
    MAX_HEADING_ABS, MAX_OBSTACLE_ABS,
};
pub use validate_live::{
    polygon_defect, Field, LiveObstacleValidator, LiveSetRejection, LiveValidatorSettingError,
    PolygonDefect, MIN_POLYGON_AREA,
};

/// Now, in nanoseconds of `CLOCK_MONOTONIC`: the clock of [`PoseEstimate::timestamp_ns`] and
/// [`Telemetry::timestamp_ns`]. Monotonic because poses are judged stale by age, which must
/// not jump with NTP; shared memory implies one host, so all processes share this clock.
/// (Rust's `Instant` uses the same clock on Linux but does not expose its value.)
pub fn monotonic_now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if rc != 0 {
        return 0;
    }
    (ts.tv_sec as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec as u64)
}
