//! Live obstacles from the wire into the pilot's terms (DESIGN §18): a set
//! [`shm_ipc::LiveObstacleValidator`] accepted, its stamps mapped onto the
//! daemon's clock. One conversion at the edge; everything after it speaks
//! [`control::live`].

use control::live::{LiveClass, LiveError, LiveObstacle, LiveSet, LiveShape};
use shm_ipc::{LiveObstacleSet, ObstacleClass, ObstacleShape};

use crate::clock::DaemonClock;

/// `wire` (validated) into `out`, stamps on `clock`. No allocation. An error
/// names the obstacle (index, id): a set the validator passed that the
/// pilot's own rules refuse (they agree; the error is the guard).
pub fn convert(
    wire: &LiveObstacleSet,
    clock: &DaemonClock,
    out: &mut LiveSet,
) -> Result<(), (usize, u32, LiveError)> {
    out.start(clock.from_monotonic_ns(wire.timestamp_ns))
        .map_err(|e| (0, 0, e))?;
    for (i, o) in wire.as_slice().iter().enumerate() {
        let fail = |e| (i, o.id, e);
        let shape = match o.shape() {
            Ok(ObstacleShape::Circle) => LiveShape::circle([o.x, o.y], o.radius),
            Ok(ObstacleShape::Polygon) => LiveShape::polygon(o.vertices()),
            Err(code) => return Err(fail(LiveError::Vertices(code as usize))),
        }
        .map_err(fail)?;
        let class = match o.class() {
            Ok(ObstacleClass::Person) => LiveClass::Person,
            Ok(ObstacleClass::Vehicle) => LiveClass::Vehicle,
            Ok(ObstacleClass::Machine) => LiveClass::Machine,
            Ok(ObstacleClass::Static) => LiveClass::Static,
            Ok(ObstacleClass::Unknown) | Err(_) => LiveClass::Unknown,
        };
        let stamp = clock.from_monotonic_ns(o.timestamp_ns);
        let live = LiveObstacle::new(o.id, class, shape, [o.vx, o.vy], stamp).map_err(fail)?;
        out.push(live).map_err(fail)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_ipc::LiveObstacle as Wire;

    #[test]
    fn a_wire_set_becomes_the_pilots_with_stamps_on_the_daemon_clock() {
        let clock = DaemonClock::new(1.0);
        let ns = clock.to_monotonic_ns(2.5);
        let mut wire = LiveObstacleSet::empty(ns, 3);
        wire.push(Wire::circle(
            7,
            ObstacleClass::Person,
            [3.0, 1.0],
            0.4,
            [0.0, 1.4],
            ns,
        ))
        .unwrap();
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        wire.push(
            Wire::polygon(
                9,
                ObstacleClass::Static,
                &square,
                [0.0, 0.0],
                clock.to_monotonic_ns(2.4),
            )
            .unwrap(),
        )
        .unwrap();
        let mut set = LiveSet::new();
        convert(&wire, &clock, &mut set).unwrap();
        assert!((set.stamp().unwrap() - 2.5).abs() < 1e-6);
        let [a, b] = set.obstacles() else {
            panic!("{set:?}")
        };
        assert_eq!(
            (a.id, a.class, a.velocity),
            (7, LiveClass::Person, [0.0, 1.4])
        );
        assert!((a.shape.signed_distance([3.0, 2.0]) - 0.6).abs() < 1e-12);
        assert_eq!((b.id, b.class), (9, LiveClass::Static));
        assert!((b.stamp - 2.4).abs() < 1e-6);
        assert!((b.shape.signed_distance([0.5, 2.0]) - 1.0).abs() < 1e-12);
        // What the pilot's rules refuse is named by index and id.
        let mut bad = LiveObstacleSet::empty(ns, 4);
        bad.push(Wire::circle(
            5,
            ObstacleClass::Person,
            [0.0, 0.0],
            0.0,
            [0.0, 0.0],
            ns,
        ))
        .unwrap();
        let (i, id, e) = convert(&bad, &clock, &mut set).unwrap_err();
        assert_eq!((i, id), (0, 5));
        assert_eq!(e, LiveError::Radius(0.0));
    }
}
