//! The site: a map of static obstacles, keep-outs and bounds, the machine's
//! outline, and a spatial index over them (DESIGN §17).
//!
//! File format `wlnav-site-v1` (JSON; unknown fields are errors, since a typo
//! in a safety file must not pass silently):
//!
//! ```text
//! { "format": "wlnav-site-v1", "id": "north-pit", "version": 3,
//!   "bounds":   [[x, y], ...],
//!   "obstacles": [
//!     { "id": "pile-1", "circle":   [x, y, r] },
//!     { "id": "berm-2", "polygon":  [[x, y], ...] },
//!     { "id": "wall-3", "polyline": [[x, y], ...], "width": 0.5 } ],
//!   "keepout":  [ { "id": "office", "polygon": [[x, y], ...] } ] }
//! ```
//!
//! Metres, the pose frame; shapes are physical outlines (no machine width in
//! them: the machine is its [`outline::Outline`]). `obstacles` and `keepout`
//! may be left out when empty.
//!
//! Loading is pure ([`Site::parse`] takes the file's bytes) and all or
//! nothing: a [`Site`] exists only when every check passed, so a caller that
//! keeps its old site on any error never holds a half-loaded one.
//!
//! Limits, so that load time and memory are bounded whatever the file says:
//! [`MAX_FILE_BYTES`], [`MAX_FEATURES`], [`MAX_SHAPE_VERTICES`] per shape
//! (the simplicity test is O(n²) in it: ≤ 0.5 M edge pairs per polygon),
//! [`MAX_TOTAL_VERTICES`].

pub mod generate;
pub mod geometry;
pub mod goals;
pub mod index;
pub mod nav2;
pub mod outline;
mod validate;

use serde::{Deserialize, Serialize};

pub use geometry::{Aabb, Circle, Nearest, Polygon, Polyline, Shape, P2};
pub use index::{Hit, Near, SiteIndex, Target};
pub use outline::{Body, Outline, OutlineCircle, WorldCircle, MAX_OUTLINE_CIRCLES};

/// The `format` string of a site file.
pub const FORMAT: &str = "wlnav-site-v1";
/// Largest site file accepted [bytes].
pub const MAX_FILE_BYTES: usize = 32 << 20;
/// Most obstacles plus keep-outs in one site.
pub const MAX_FEATURES: usize = 20_000;
/// Most vertices of one polygon, polyline or the bounds.
pub const MAX_SHAPE_VERTICES: usize = 1024;
/// Most vertices of all shapes together (a circle counts one).
pub const MAX_TOTAL_VERTICES: usize = 100_000;
/// Longest id (site or feature) [bytes].
pub const MAX_ID_BYTES: usize = 64;
/// How far a feature may stick out of the bounds and still count as inside
/// [m]: rounding only (an imported map's cells touch its bounds).
pub const BOUNDS_TOLERANCE: f64 = 1e-6;

/// A site file, field for field (what [`Site::parse`] reads and
/// [`SiteFile::to_json`] writes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteFile {
    pub format: String,
    pub id: String,
    pub version: u64,
    pub bounds: Vec<P2>,
    #[serde(default)]
    pub obstacles: Vec<ObstacleEntry>,
    #[serde(default)]
    pub keepout: Vec<KeepoutEntry>,
}

/// One obstacle of a site file: an id and exactly one shape.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleEntry {
    pub id: String,
    /// [x, y, r].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub circle: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub polygon: Option<Vec<P2>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub polyline: Option<Vec<P2>>,
    /// The polyline's full width [m] (only with `polyline`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<f64>,
}

/// One keep-out zone of a site file: a polygon nobody may drive into.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeepoutEntry {
    pub id: String,
    pub polygon: Vec<P2>,
}

impl SiteFile {
    /// The file's JSON text: the header, then one feature per line (short
    /// diffs when a site changes, readable without a formatter).
    pub fn to_json(&self) -> String {
        // Strings, integers and finite floats always serialise.
        fn j<T: Serialize + ?Sized>(v: &T) -> String {
            serde_json::to_string(v).unwrap_or_default()
        }
        let list = |items: Vec<String>| {
            if items.is_empty() {
                "[]".to_string()
            } else {
                format!("[\n    {}\n  ]", items.join(",\n    "))
            }
        };
        format!(
            "{{\n  \"format\": {},\n  \"id\": {},\n  \"version\": {},\n  \"bounds\": {},\n  \"obstacles\": {},\n  \"keepout\": {}\n}}\n",
            j(&self.format),
            j(&self.id),
            self.version,
            j(&self.bounds),
            list(self.obstacles.iter().map(j).collect()),
            list(self.keepout.iter().map(j).collect()),
        )
    }
}

/// What a feature is to the machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FeatureKind {
    /// Something physical the outline must not touch.
    Obstacle,
    /// An area the outline must not enter (an office, a fuel station).
    KeepOut,
}

impl std::fmt::Display for FeatureKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FeatureKind::Obstacle => "obstacle",
            FeatureKind::KeepOut => "keep-out",
        })
    }
}

/// One validated feature.
#[derive(Debug, Clone, PartialEq)]
pub struct Feature {
    pub id: String,
    pub kind: FeatureKind,
    pub shape: Shape,
}

/// What is wrong with one feature (or the bounds).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeatureProblem {
    #[error("{0}")]
    Entry(String),
    #[error("has no shape (give one of `circle`, `polygon`, `polyline`)")]
    NoShape,
    #[error("has more than one shape (give one of `circle`, `polygon`, `polyline`)")]
    SeveralShapes,
    #[error("has a `width` but no `polyline`")]
    WidthWithoutPolyline,
    #[error("is a `polyline` without a `width`")]
    MissingWidth,
    #[error("vertex {vertex} is not finite")]
    NotFinite { vertex: usize },
    #[error("radius must be finite and > 0 (got {0})")]
    NonPositiveRadius(f64),
    #[error("width must be finite and > 0 (got {0})")]
    NonPositiveWidth(f64),
    #[error("has {found} vertices, needs at least {min}")]
    TooFewVertices { found: usize, min: usize },
    #[error("has {found} vertices, more than the limit of {limit}")]
    TooManyVertices { found: usize, limit: usize },
    #[error(
        "vertex {vertex} repeats vertex {earlier} (zero-length edge; the ring closes by itself)"
    )]
    RepeatedVertex { vertex: usize, earlier: usize },
    #[error("is not simple: edge {edge_a} meets edge {edge_b}")]
    SelfIntersection { edge_a: usize, edge_b: usize },
    #[error("has zero area")]
    ZeroArea,
    #[error("is not inside the bounds: {detail}")]
    OutsideBounds { detail: String },
    #[error("id {0}")]
    BadId(&'static str),
}

/// Why a site was not loaded. Every variant names what is wrong and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SiteError {
    #[error("site file is {size} bytes, more than the limit of {limit}")]
    FileTooLarge { size: usize, limit: usize },
    #[error("site file, line {line} column {column}: {message}")]
    Json {
        line: usize,
        column: usize,
        message: String,
    },
    #[error("site file: format is {found:?}, expected {FORMAT:?}")]
    Format { found: String },
    #[error("site id {0}")]
    BadSiteId(&'static str),
    #[error("bounds {0}")]
    Bounds(FeatureProblem),
    #[error("{kind} `{id}` {problem}")]
    Feature {
        kind: FeatureKind,
        id: String,
        problem: FeatureProblem,
    },
    /// An entry whose id could not be read, named by its place in the file.
    #[error("{list}[{index}]: {problem}")]
    Entry {
        list: &'static str,
        index: usize,
        problem: FeatureProblem,
    },
    #[error("feature id `{id}` is used twice")]
    DuplicateId { id: String },
    #[error("the site has {found} {what}, more than the limit of {limit}")]
    Limit {
        what: &'static str,
        found: usize,
        limit: usize,
    },
}

/// FNV-1a, 64 bit: the site's content hash (of the file's bytes), shown with
/// its id and version so two machines can tell they hold the same map. Not a
/// cryptographic hash: it detects accidents, not forgeries.
pub fn content_hash(bytes: &[u8]) -> u64 {
    content_hash_extend(0xcbf2_9ce4_8422_2325, bytes)
}

/// Continues an FNV-1a hash over more bytes (for a map of several files).
pub fn content_hash_extend(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// A loaded, validated site: immutable once built.
#[derive(Debug, Clone, PartialEq)]
pub struct Site {
    id: String,
    version: u64,
    hash: u64,
    bounds: Polygon,
    features: Vec<Feature>,
}

/// The file parsed loosely, entries kept as JSON values, so that an entry's
/// error can name its id ([`attribute`]).
#[derive(Deserialize)]
struct RawSiteFile {
    #[serde(default)]
    obstacles: Vec<serde_json::Value>,
    #[serde(default)]
    keepout: Vec<serde_json::Value>,
}

fn check_id(id: &str) -> Result<(), &'static str> {
    if id.is_empty() {
        return Err("is empty");
    }
    if id.len() > MAX_ID_BYTES {
        return Err("is longer than 64 bytes");
    }
    if id.chars().any(|c| c.is_control()) {
        return Err("contains a control character");
    }
    Ok(())
}

fn json_error(e: &serde_json::Error) -> SiteError {
    let full = e.to_string();
    // serde_json appends " at line L column C"; the position has its own fields.
    let message = match full.rfind(" at line ") {
        Some(k) => full[..k].to_string(),
        None => full,
    };
    SiteError::Json {
        line: e.line(),
        column: e.column(),
        message,
    }
}

/// Reads one entry (an obstacle or keep-out) out of its JSON value; errors
/// name its id when it has a readable one, else its place in the list.
/// `position` (from the strict parse) is appended to the message.
fn entry<T: serde::de::DeserializeOwned>(
    v: serde_json::Value,
    list: &'static str,
    index: usize,
    kind: FeatureKind,
    position: (usize, usize),
) -> Result<T, SiteError> {
    let id = v.get("id").and_then(|x| x.as_str()).map(str::to_string);
    serde_json::from_value(v).map_err(|e| {
        let problem =
            FeatureProblem::Entry(format!("{e} (line {} column {})", position.0, position.1));
        match id {
            Some(id) if check_id(&id).is_ok() => SiteError::Feature { kind, id, problem },
            _ => SiteError::Entry {
                list,
                index,
                problem,
            },
        }
    })
}

/// Names the entry a strict parse's data error is in (an unknown or missing
/// field, a wrong type): the loose parse keeps entries as JSON values, and
/// the first that does not read names itself. `None` when no entry fails
/// that way (a top-level field, or a repeated key, which a JSON value
/// silently merges): the strict error then stands as it is.
fn attribute(bytes: &[u8], strict: &serde_json::Error) -> Option<SiteError> {
    let raw: RawSiteFile = serde_json::from_slice(bytes).ok()?;
    let at = (strict.line(), strict.column());
    for (i, v) in raw.obstacles.into_iter().enumerate() {
        if let Err(e) = entry::<ObstacleEntry>(v, "obstacles", i, FeatureKind::Obstacle, at) {
            return Some(e);
        }
    }
    for (i, v) in raw.keepout.into_iter().enumerate() {
        if let Err(e) = entry::<KeepoutEntry>(v, "keepout", i, FeatureKind::KeepOut, at) {
            return Some(e);
        }
    }
    None
}

impl Site {
    /// Parses and validates a site file's bytes; the content hash is of
    /// these bytes.
    pub fn parse(bytes: &[u8]) -> Result<Site, SiteError> {
        if bytes.len() > MAX_FILE_BYTES {
            return Err(SiteError::FileTooLarge {
                size: bytes.len(),
                limit: MAX_FILE_BYTES,
            });
        }
        // Strict first: unknown fields and repeated keys anywhere are errors
        // with a line and column. A data error inside an entry is then
        // attributed to the entry's id by a second, loose parse.
        let file: SiteFile = match serde_json::from_slice(bytes) {
            Ok(f) => f,
            Err(e) if e.is_data() => {
                return Err(attribute(bytes, &e).unwrap_or_else(|| json_error(&e)))
            }
            Err(e) => return Err(json_error(&e)),
        };
        Site::from_file(file, content_hash(bytes))
    }

    /// Validates a site file already in memory (an import, a generator);
    /// `hash` is what [`Site::hash`] will report.
    pub fn from_file(file: SiteFile, hash: u64) -> Result<Site, SiteError> {
        if file.format != FORMAT {
            return Err(SiteError::Format { found: file.format });
        }
        check_id(&file.id).map_err(SiteError::BadSiteId)?;
        let count = file.obstacles.len() + file.keepout.len();
        if count > MAX_FEATURES {
            return Err(SiteError::Limit {
                what: "features",
                found: count,
                limit: MAX_FEATURES,
            });
        }
        let total: usize = file.bounds.len()
            + file
                .obstacles
                .iter()
                .map(|o| {
                    o.polygon.as_ref().map_or(0, Vec::len)
                        + o.polyline.as_ref().map_or(0, Vec::len)
                        + usize::from(o.circle.is_some())
                })
                .sum::<usize>()
            + file.keepout.iter().map(|k| k.polygon.len()).sum::<usize>();
        if total > MAX_TOTAL_VERTICES {
            return Err(SiteError::Limit {
                what: "vertices",
                found: total,
                limit: MAX_TOTAL_VERTICES,
            });
        }
        validate::simple_polygon(&file.bounds).map_err(SiteError::Bounds)?;
        let bounds = Polygon::new(file.bounds);

        let mut seen = std::collections::HashSet::with_capacity(count);
        let mut features = Vec::with_capacity(count);
        let named = |list: &'static str, index: usize, kind: FeatureKind, id: &str| {
            check_id(id).map_err(|why| SiteError::Entry {
                list,
                index,
                problem: FeatureProblem::BadId(why),
            })?;
            let id = id.to_string();
            Ok::<_, SiteError>(move |problem| SiteError::Feature { kind, id, problem })
        };
        for (i, o) in file.obstacles.into_iter().enumerate() {
            let err = named("obstacles", i, FeatureKind::Obstacle, &o.id)?;
            let shape = obstacle_shape(&o, &bounds).map_err(err)?;
            if !seen.insert(o.id.clone()) {
                return Err(SiteError::DuplicateId { id: o.id });
            }
            features.push(Feature {
                id: o.id,
                kind: FeatureKind::Obstacle,
                shape,
            });
        }
        for (i, k) in file.keepout.into_iter().enumerate() {
            let err = named("keepout", i, FeatureKind::KeepOut, &k.id)?;
            validate::simple_polygon(&k.polygon)
                .and_then(|()| validate::polygon_inside(&bounds, &k.polygon))
                .map_err(err)?;
            if !seen.insert(k.id.clone()) {
                return Err(SiteError::DuplicateId { id: k.id });
            }
            features.push(Feature {
                id: k.id,
                kind: FeatureKind::KeepOut,
                shape: Shape::Polygon(Polygon::new(k.polygon)),
            });
        }
        Ok(Site {
            id: file.id,
            version: file.version,
            hash,
            bounds,
            features,
        })
    }

    /// The site's id (the fleet's map id).
    pub fn id(&self) -> &str {
        &self.id
    }

    pub fn version(&self) -> u64 {
        self.version
    }

    /// FNV-1a 64 of the loaded bytes ([`content_hash`]).
    pub fn hash(&self) -> u64 {
        self.hash
    }

    /// The hash as 16 hex digits, as telemetry and `wlnav status` show it.
    pub fn hash_hex(&self) -> String {
        format!("{:016x}", self.hash)
    }

    /// The area the machine's outline must stay inside.
    pub fn bounds(&self) -> &Polygon {
        &self.bounds
    }

    /// Obstacles first, in file order, then keep-outs in file order.
    pub fn features(&self) -> &[Feature] {
        &self.features
    }

    /// The feature of this id.
    pub fn find(&self, id: &str) -> Option<(usize, &Feature)> {
        self.features.iter().enumerate().find(|(_, f)| f.id == id)
    }

    /// The site as a file again (its JSON re-parses to an equal site).
    pub fn to_file(&self) -> SiteFile {
        let mut obstacles = Vec::new();
        let mut keepout = Vec::new();
        for f in &self.features {
            match (f.kind, &f.shape) {
                (FeatureKind::KeepOut, Shape::Polygon(g)) => keepout.push(KeepoutEntry {
                    id: f.id.clone(),
                    polygon: g.vertices().to_vec(),
                }),
                (_, shape) => {
                    let mut e = ObstacleEntry {
                        id: f.id.clone(),
                        ..Default::default()
                    };
                    match shape {
                        Shape::Circle(c) => e.circle = Some([c.center[0], c.center[1], c.radius]),
                        Shape::Polygon(g) => e.polygon = Some(g.vertices().to_vec()),
                        Shape::Polyline(l) => {
                            e.polyline = Some(l.vertices().to_vec());
                            e.width = Some(2.0 * l.half_width());
                        }
                    }
                    obstacles.push(e);
                }
            }
        }
        SiteFile {
            format: FORMAT.to_string(),
            id: self.id.clone(),
            version: self.version,
            bounds: self.bounds.vertices().to_vec(),
            obstacles,
            keepout,
        }
    }
}

fn obstacle_shape(o: &ObstacleEntry, bounds: &Polygon) -> Result<Shape, FeatureProblem> {
    let shapes = usize::from(o.circle.is_some())
        + usize::from(o.polygon.is_some())
        + usize::from(o.polyline.is_some());
    match shapes {
        0 => return Err(FeatureProblem::NoShape),
        1 => {}
        _ => return Err(FeatureProblem::SeveralShapes),
    }
    if o.width.is_some() && o.polyline.is_none() {
        return Err(FeatureProblem::WidthWithoutPolyline);
    }
    if let Some(c) = o.circle {
        validate::circle(c)?;
        validate::circle_inside(bounds, [c[0], c[1]], c[2])?;
        return Ok(Shape::Circle(Circle {
            center: [c[0], c[1]],
            radius: c[2],
        }));
    }
    if let Some(ring) = &o.polygon {
        validate::simple_polygon(ring)?;
        validate::polygon_inside(bounds, ring)?;
        return Ok(Shape::Polygon(Polygon::new(ring.clone())));
    }
    let line = o.polyline.as_ref().ok_or(FeatureProblem::NoShape)?;
    let width = o.width.ok_or(FeatureProblem::MissingWidth)?;
    validate::polyline(line, width)?;
    let l = Polyline::new(line.clone(), width);
    validate::polyline_inside(bounds, &l)?;
    Ok(Shape::Polyline(l))
}

#[cfg(test)]
mod tests;
