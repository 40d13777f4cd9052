// An independently written VDA 5050 master drives wlnav-fleet: vda-5050-lib 1.4.0's
// MasterController (Siemens' open-source client), run by fleet/tests/master.rs against
// mosquitto, wlnavd --sim and wlnav-fleet.
//
//   node master.mjs --broker 127.0.0.1:PORT --manufacturer wlnav --serials L1,L2 --schemas DIR
//
// For every vehicle at once: a 3-node order (A -> B passed within 0.5 m -> C, D as horizon)
// to completion node by node; an order update releasing D; a second order cancelled while
// driving (cancelOrder); a third order paused and resumed (startPause / stopPause). Every
// state, visualization, connection and factsheet message received is validated here against
// the official JSON schemas (fleet/schemas/) with Ajv (draft 2020-12), the library's own
// inbound validation off; each vehicle must send each of them, and every message must reach
// the master's handlers (none dropped). Exit 0 when all holds.
//
// vda-5050-lib 1.4.0 sends instant actions under the key `instantActions` (VDA 5050 1.1's
// name); the 2.0.0 schema requires `actions`. The bridge refuses such a message (a
// validationError in state), so this master renames the key on the wire: the library's
// known bug, worked around on the master's side.

import lib from "vda-5050-lib";
import { compileSchemas } from "./schemas.mjs";

const { MasterController, Topic } = lib;

function arg(name) {
  const i = process.argv.indexOf(`--${name}`);
  if (i < 0 || i + 1 >= process.argv.length) throw new Error(`missing --${name}`);
  return process.argv[i + 1];
}

const broker = arg("broker");
const manufacturer = arg("manufacturer");
const serials = arg("serials").split(",");
const schemaDir = arg("schemas");

// ---- schemas --------------------------------------------------------------------------
// Every message is validated here, against the official schemas. The library's own inbound
// validation is off (topicObjectValidation.inbound below): it drops an invalid message
// with a console line before any handler, so the check here would never see it. Counts are
// per vehicle and topic, of what arrived on the wire (`received`) and of what reached this
// master's handlers through the library (`delivered`): any difference is a dropped message,
// and fails the run.
const { ajv, validators } = compileSchemas(schemaDir);
const received = {};
const delivered = {};
const invalid = [];
const dropped = [];
const bump = (table, serial, topic) => {
  table[serial] ??= {};
  table[serial][topic] = (table[serial][topic] ?? 0) + 1;
};
function check(topic, msg, serial) {
  if (!validators[topic](msg)) {
    invalid.push(`${serial} ${topic}: ${ajv.errorsText(validators[topic].errors)}: ${JSON.stringify(msg)}`);
  }
}
// Whatever the library still drops (a payload that is not JSON, a handler's error) it
// reports on console.error: a failure here.
const consoleError = console.error.bind(console);
console.error = (...args) => {
  if (typeof args[0] === "string" && args[0].startsWith("Drop inbound message")) dropped.push(args.map(String).join(" "));
  consoleError(...args);
};

// Wall-clock limits scale with WLNAV_TIMING_SCALE (tests/timing_scale.rs: a number >= 1).
const timingScale = (() => {
  const v = process.env.WLNAV_TIMING_SCALE;
  if (v === undefined || v.trim() === "") return 1;
  const f = Number(v);
  if (!Number.isFinite(f) || f < 1) throw new Error(`WLNAV_TIMING_SCALE=${v}: must be a number >= 1`);
  return f;
})();

// ---- helpers --------------------------------------------------------------------------
const log = (...a) => console.log(new Date().toISOString(), ...a);
function fail(msg) {
  console.error(`master: FAILED: ${msg}`);
  process.exit(1);
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
function withTimeout(promise, ms, what) {
  const limit = ms * timingScale;
  return Promise.race([promise, sleep(limit).then(() => { throw new Error(`timeout after ${limit} ms: ${what}`); })]);
}

const lastState = new Map();
const stateWaiters = [];
function onState(serial, state) {
  lastState.set(serial, state);
  for (const w of [...stateWaiters]) {
    if (w.serial === serial && w.pred(state)) {
      stateWaiters.splice(stateWaiters.indexOf(w), 1);
      w.resolve(state);
    }
  }
}
function waitState(serial, pred, ms, what) {
  const s = lastState.get(serial);
  if (s && pred(s)) return Promise.resolve(s);
  return withTimeout(new Promise((resolve) => stateWaiters.push({ serial, pred, resolve })), ms, `${serial}: ${what}`);
}

function node(id, seq, x, y, dev, released = true) {
  return {
    nodeId: id, sequenceId: seq, released, actions: [],
    nodePosition: { x, y, mapId: "site", allowedDeviationXY: dev },
  };
}
function edges(nodes) {
  const out = [];
  for (let i = 0; i + 1 < nodes.length; i++) {
    out.push({
      edgeId: `${nodes[i].nodeId}-${nodes[i + 1].nodeId}`, sequenceId: nodes[i].sequenceId + 1,
      released: nodes[i + 1].released, startNodeId: nodes[i].nodeId, endNodeId: nodes[i + 1].nodeId, actions: [],
    });
  }
  return out;
}
function order(orderId, orderUpdateId, nodes) {
  return { orderId, orderUpdateId, nodes, edges: edges(nodes) };
}

// Assigns an order; resolves with { traversed, result } when onOrderProcessed fires.
function assign(mc, agv, o) {
  const traversed = [];
  return new Promise((resolve, reject) => {
    mc.assignOrder(agv, o, {
      onOrderProcessed: (error, byCancelation, active, ctx) =>
        resolve({ traversed, error, byCancelation, active, state: ctx.state }),
      onNodeTraversed: (n) => traversed.push(n.nodeId),
    }).catch(reject);
  });
}

// Initiates one instant action; resolves once it ends (FINISHED or FAILED).
function instant(mc, agv, actionType, actionId) {
  const statuses = [];
  return new Promise((resolve, reject) => {
    mc.initiateInstantActions(agv, {
      instantActions: [{ actionType, actionId, blockingType: "HARD" }],
    }, {
      onActionStateChanged: (as, error) => {
        statuses.push(as.actionStatus);
        if (as.actionStatus === "FINISHED" || as.actionStatus === "FAILED") resolve({ statuses, error });
      },
      onActionError: (error) => reject(new Error(`${actionType}: ${JSON.stringify(error)}`)),
    }).catch(reject);
  });
}

// ---- the run --------------------------------------------------------------------------
const mc = new MasterController(
  {
    interfaceName: "uagv", transport: { brokerUrl: `mqtt://${broker}` }, vdaVersion: "2.0.0",
    topicObjectValidation: { inbound: false },
  },
  { targetAgvs: { manufacturer } },
);
await mc.start();
// The 1.4.0 instantActions key bug (see the top of this file).
const mqtt = mc._mqtt;
const rawPublish = mqtt.publish.bind(mqtt);
mqtt.publish = (topic, payload, ...rest) => {
  if (topic.endsWith("/instantActions")) {
    const msg = JSON.parse(payload);
    if (msg.instantActions && !msg.actions) {
      msg.actions = msg.instantActions;
      delete msg.instantActions;
    }
    check("instantActions", msg, topic.split("/")[3]);
    payload = JSON.stringify(msg);
  } else if (topic.endsWith("/order")) {
    check("order", JSON.parse(payload), topic.split("/")[3]);
  }
  return rawPublish(topic, payload, ...rest);
};

// Every inbound message on the wire, before the library: counted and validated. The
// library's listener was added first (mc.start), so on each message it has run its
// handlers (counted in `delivered`) before this one counts it as received.
const inboundTopics = ["state", "visualization", "connection", "factsheet"];
mqtt.on("message", (topic, payload) => {
  const [, , m, serial, name] = topic.split("/");
  if (m !== manufacturer || !serials.includes(serial) || !inboundTopics.includes(name)) return;
  bump(received, serial, name);
  let msg;
  try {
    msg = JSON.parse(payload.toString());
  } catch (e) {
    invalid.push(`${serial} ${name}: not JSON (${e.message}): ${payload.toString().slice(0, 200)}`);
    return;
  }
  check(name, msg, serial);
});

const agvs = serials.map((serialNumber) => ({ manufacturer, serialNumber }));
for (const agv of agvs) {
  const s = agv.serialNumber;
  await mc.subscribe(Topic.State, agv, (st) => { bump(delivered, s, "state"); onState(s, st); });
  await mc.subscribe(Topic.Visualization, agv, () => bump(delivered, s, "visualization"));
  await mc.subscribe(Topic.Connection, agv, () => bump(delivered, s, "connection"));
  await mc.subscribe(Topic.Factsheet, agv, () => bump(delivered, s, "factsheet"));
}

async function drive(agv) {
  const s = agv.serialNumber;
  const ready = (st) => st.operatingMode === "AUTOMATIC" && st.errors.length === 0 && st.agvPosition?.positionInitialized;
  await waitState(s, ready, 60000, "ready");
  log(s, "ready");

  // 1. Three released nodes (B passed within 0.5 m) and a horizon node D.
  const base = [node("A", 0, 0, 0, 0), node("B", 2, 3, 0, 0.5), node("C", 4, 6, 0, 0), node("D", 6, 9, 0, 0, false)];
  let r = await withTimeout(assign(mc, agv, order(`${s}-o1`, 0, base)), 90000, `${s}: order o1`);
  if (r.error) fail(`${s}: o1 rejected: ${JSON.stringify(r.error)}`);
  if (r.traversed.join() !== "A,B,C") fail(`${s}: o1 traversed ${r.traversed}`);
  if (!r.active) fail(`${s}: o1 should stay active (horizon D)`);
  if (r.state.lastNodeId !== "C" || r.state.driving) fail(`${s}: o1 should end at rest on C: ${JSON.stringify(r.state)}`);
  log(s, "o1 processed node by node:", r.traversed.join(" -> "), "(D on the horizon)");

  // 2. The update stitches at C and releases D.
  r = await withTimeout(assign(mc, agv, order(`${s}-o1`, 1, [node("C", 4, 6, 0, 0), node("D", 6, 9, 0, 0)])), 90000, `${s}: update`);
  if (r.error) fail(`${s}: update rejected: ${JSON.stringify(r.error)}`);
  if (!r.traversed.includes("D") || r.active) fail(`${s}: update traversed ${r.traversed}, active ${r.active}`);
  log(s, "update processed:", r.traversed.join(" -> "));

  // 3. Cancel while driving.
  let pos = lastState.get(s).agvPosition;
  const o2 = assign(mc, agv, order(`${s}-o2`, 0, [node("D", 0, pos.x, pos.y, 0.5), node("E", 2, pos.x + 8, pos.y, 0)]));
  await waitState(s, (st) => st.orderId === `${s}-o2` && st.driving, 30000, "o2 driving");
  const cancel = await withTimeout(instant(mc, agv, "cancelOrder", `${s}-cancel`), 30000, `${s}: cancel`);
  if (cancel.statuses.at(-1) !== "FINISHED") fail(`${s}: cancel ${cancel.statuses}`);
  r = await withTimeout(o2, 30000, `${s}: o2 processed`);
  if (!r.byCancelation) fail(`${s}: o2 should end by cancelation`);
  const afterCancel = lastState.get(s);
  if (afterCancel.driving || afterCancel.nodeStates.length !== 0) fail(`${s}: after cancel: ${JSON.stringify(afterCancel)}`);
  log(s, "cancel:", cancel.statuses.join(" -> "));

  // 4. Pause and resume on the way.
  pos = afterCancel.agvPosition;
  const o3 = assign(mc, agv, order(`${s}-o3`, 0, [node("P", 0, pos.x, pos.y, 0.5), node("Q", 2, pos.x + 5, pos.y, 0)]));
  await waitState(s, (st) => st.orderId === `${s}-o3` && st.driving, 30000, "o3 driving");
  const pause = await withTimeout(instant(mc, agv, "startPause", `${s}-pause`), 30000, `${s}: pause`);
  if (pause.statuses.at(-1) !== "FINISHED") fail(`${s}: startPause ${pause.statuses}`);
  const paused = await waitState(s, (st) => st.paused === true && !st.driving, 10000, "paused at rest");
  await sleep(1000);
  const still = lastState.get(s);
  const moved = Math.hypot(still.agvPosition.x - paused.agvPosition.x, still.agvPosition.y - paused.agvPosition.y);
  if (moved > 0.05 || still.lastNodeId !== "P") fail(`${s}: moved ${moved} m while paused`);
  const resume = await withTimeout(instant(mc, agv, "stopPause", `${s}-resume`), 30000, `${s}: resume`);
  if (resume.statuses.at(-1) !== "FINISHED") fail(`${s}: stopPause ${resume.statuses}`);
  r = await withTimeout(o3, 90000, `${s}: o3 after resume`);
  if (r.error || r.traversed.at(-1) !== "Q") fail(`${s}: o3 ${JSON.stringify(r)}`);
  if (lastState.get(s).paused) fail(`${s}: still paused`);
  log(s, "pause/resume: o3 completed", r.traversed.join(" -> "));
}

try {
  await Promise.all(agvs.map(drive));
} catch (e) {
  fail(e.message);
}
await sleep(300);
await mc.stop();
if (invalid.length > 0) fail(`${invalid.length} messages fail their schema:\n${invalid.slice(0, 5).join("\n")}`);
if (dropped.length > 0) fail(`the library dropped ${dropped.length} inbound messages:\n${dropped.slice(0, 5).join("\n")}`);
for (const s of serials) {
  for (const t of inboundTopics) {
    const r = received[s]?.[t] ?? 0;
    const d = delivered[s]?.[t] ?? 0;
    if (r === 0) fail(`${s}: no ${t} message received`);
    if (d !== r) fail(`${s}: ${r} ${t} messages received, ${d} reached the master (${r - d} dropped)`);
  }
}
log("master: all steps done; schema-valid messages per vehicle:", JSON.stringify(received));
process.exit(0);
