//! Import of a ROS / Nav2 `map_server` map (YAML + PGM) as a site (DESIGN
//! §17): occupied cells become rectangle polygons (runs of a row, merged
//! with identical runs of the rows below), the image's extent the bounds.
//!
//! Pure: the caller reads the YAML, then the image its `image` key names
//! (relative to the YAML's directory, as `map_server` does), and hands both
//! over as text and bytes.
//!
//! The YAML is the map_server's flat format, parsed here by hand for its keys
//! (`image`, `resolution`, `origin: [x, y, yaw]`, `negate`, `occupied_thresh`,
//! `free_thresh`, optional `mode`: `trinary` (the default) or `scale`; `raw`
//! is refused). Unknown keys are errors, naming the line, as in a site file.
//!
//! A pixel's occupancy follows map_server: p = (maxval − v) / maxval, or
//! v / maxval with `negate`; occupied if p > occupied_thresh, free if
//! p < free_thresh, unknown otherwise. Unknown cells are obstacles unless
//! [`ImportOptions::unknown_is_free`] (a map's unexplored parts are not known
//! to be drivable). `origin` is the pose of the image's lower-left pixel; its
//! yaw (counter-clockwise) is honoured, though many ROS tools ignore it.

use super::{
    content_hash, content_hash_extend, ObstacleEntry, Site, SiteError, SiteFile, FORMAT,
    MAX_FEATURES,
};

/// Most pixels of an imported image (an 8192 × 8192 map).
pub const MAX_PIXELS: usize = 1 << 26;

/// Why a map was not imported.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapError {
    #[error("map YAML, line {line}: {message}")]
    Yaml { line: usize, message: String },
    #[error("map YAML: key `{0}` is missing")]
    MissingKey(&'static str),
    #[error("map YAML: `{key}` {message}")]
    BadValue { key: &'static str, message: String },
    #[error("map image: {0}")]
    Pgm(String),
    #[error("map: {found} occupied rectangles, more than a site's limit of {limit} features")]
    TooManyFeatures { found: usize, limit: usize },
    #[error("map: {0}")]
    Site(#[from] SiteError),
}

/// How a map's pixels are read (map_server's `mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapMode {
    Trinary,
    Scale,
}

/// A map_server YAML file's values.
#[derive(Debug, Clone, PartialEq)]
pub struct MapYaml {
    /// The image's path as written (relative to the YAML's directory).
    pub image: String,
    /// Metres per pixel.
    pub resolution: f64,
    /// Pose of the lower-left pixel: [x, y, yaw].
    pub origin: [f64; 3],
    pub negate: bool,
    pub occupied_thresh: f64,
    pub free_thresh: f64,
    pub mode: MapMode,
}

fn strip_comment(line: &str) -> &str {
    let mut quote = None;
    for (i, ch) in line.char_indices() {
        match (quote, ch) {
            (None, '"' | '\'') => quote = Some(ch),
            (Some(q), c) if c == q => quote = None,
            (None, '#') => return &line[..i],
            _ => {}
        }
    }
    line
}

fn unquote(v: &str) -> &str {
    let b = v.as_bytes();
    if b.len() >= 2 && (b[0] == b'"' || b[0] == b'\'') && b[b.len() - 1] == b[0] {
        &v[1..v.len() - 1]
    } else {
        v
    }
}

impl MapYaml {
    /// Parses the YAML text.
    pub fn parse(text: &str) -> Result<MapYaml, MapError> {
        let mut image = None;
        let mut resolution = None;
        let mut origin = None;
        let mut negate = None;
        let mut occ = None;
        let mut free = None;
        let mut mode = MapMode::Trinary;
        for (k, raw) in text.lines().enumerate() {
            let line = k + 1;
            let l = strip_comment(raw).trim();
            if l.is_empty() || l == "---" {
                continue;
            }
            let err = |message: String| MapError::Yaml { line, message };
            let (key, value) = l
                .split_once(':')
                .ok_or_else(|| err(format!("expected `key: value`, found {l:?}")))?;
            let (key, value) = (key.trim(), value.trim());
            let number = |v: &str| {
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| err(format!("`{key}` must be a finite number, found {v:?}")))
            };
            match key {
                "image" => {
                    let v = unquote(value);
                    if v.is_empty() {
                        return Err(err("`image` is empty".into()));
                    }
                    image = Some(v.to_string());
                }
                "resolution" => resolution = Some(number(value)?),
                "occupied_thresh" => occ = Some(number(value)?),
                "free_thresh" => free = Some(number(value)?),
                "negate" => {
                    negate = Some(match value {
                        "0" | "false" | "False" => false,
                        "1" | "true" | "True" => true,
                        _ => return Err(err(format!("`negate` must be 0 or 1, found {value:?}"))),
                    })
                }
                "mode" => {
                    mode = match unquote(value) {
                        "trinary" => MapMode::Trinary,
                        "scale" => MapMode::Scale,
                        other => {
                            return Err(err(format!(
                                "`mode` {other:?} is not supported (trinary or scale)"
                            )))
                        }
                    }
                }
                "origin" => {
                    let inner = value
                        .strip_prefix('[')
                        .and_then(|v| v.strip_suffix(']'))
                        .ok_or_else(|| {
                            err(format!("`origin` must be [x, y, yaw], found {value:?}"))
                        })?;
                    let parts: Vec<&str> = inner.split(',').map(str::trim).collect();
                    if parts.len() != 3 {
                        return Err(err(format!(
                            "`origin` must have 3 numbers [x, y, yaw], found {}",
                            parts.len()
                        )));
                    }
                    origin = Some([number(parts[0])?, number(parts[1])?, number(parts[2])?]);
                }
                other => return Err(err(format!("unknown key `{other}`"))),
            }
        }
        let y = MapYaml {
            image: image.ok_or(MapError::MissingKey("image"))?,
            resolution: resolution.ok_or(MapError::MissingKey("resolution"))?,
            origin: origin.ok_or(MapError::MissingKey("origin"))?,
            negate: negate.ok_or(MapError::MissingKey("negate"))?,
            occupied_thresh: occ.ok_or(MapError::MissingKey("occupied_thresh"))?,
            free_thresh: free.ok_or(MapError::MissingKey("free_thresh"))?,
            mode,
        };
        if y.resolution <= 0.0 {
            return Err(MapError::BadValue {
                key: "resolution",
                message: format!("must be > 0 (got {})", y.resolution),
            });
        }
        for (key, v) in [
            ("occupied_thresh", y.occupied_thresh),
            ("free_thresh", y.free_thresh),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(MapError::BadValue {
                    key,
                    message: format!("must be within [0, 1] (got {v})"),
                });
            }
        }
        if y.free_thresh > y.occupied_thresh {
            return Err(MapError::BadValue {
                key: "free_thresh",
                message: format!(
                    "must not exceed occupied_thresh ({} > {})",
                    y.free_thresh, y.occupied_thresh
                ),
            });
        }
        Ok(y)
    }
}

/// An 8-bit greyscale image (PGM P5 or P2), row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Pgm {
    pub width: usize,
    pub height: usize,
    pub maxval: u8,
    pub pixels: Vec<u8>,
}

impl Pgm {
    /// Parses a PGM file's bytes (binary P5 or plain P2, maxval ≤ 255).
    pub fn parse(bytes: &[u8]) -> Result<Pgm, MapError> {
        let bad = |m: &str| MapError::Pgm(m.to_string());
        let mut pos = 0;
        // Header tokens: magic, width, height, maxval; '#' comments to the
        // end of the line.
        let next_token = |pos: &mut usize| -> Option<String> {
            loop {
                while *pos < bytes.len() && bytes[*pos].is_ascii_whitespace() {
                    *pos += 1;
                }
                if *pos < bytes.len() && bytes[*pos] == b'#' {
                    while *pos < bytes.len() && bytes[*pos] != b'\n' {
                        *pos += 1;
                    }
                    continue;
                }
                break;
            }
            let s = *pos;
            while *pos < bytes.len() && !bytes[*pos].is_ascii_whitespace() && bytes[*pos] != b'#' {
                *pos += 1;
            }
            (*pos > s).then(|| String::from_utf8_lossy(&bytes[s..*pos]).into_owned())
        };
        let magic = next_token(&mut pos).ok_or_else(|| bad("empty file"))?;
        let binary = match magic.as_str() {
            "P5" => true,
            "P2" => false,
            m => {
                return Err(MapError::Pgm(format!(
                    "magic {m:?} is not a greyscale PGM (P5 or P2)"
                )))
            }
        };
        let num = |what: &str, pos: &mut usize| -> Result<usize, MapError> {
            next_token(pos)
                .and_then(|t| t.parse::<usize>().ok())
                .ok_or_else(|| MapError::Pgm(format!("header: {what} is missing or not a number")))
        };
        let width = num("width", &mut pos)?;
        let height = num("height", &mut pos)?;
        let maxval = num("maxval", &mut pos)?;
        if width == 0 || height == 0 {
            return Err(bad("width and height must be > 0"));
        }
        let count = width
            .checked_mul(height)
            .filter(|&c| c <= MAX_PIXELS)
            .ok_or_else(|| {
                MapError::Pgm(format!(
                    "{width} × {height} pixels, more than the limit of {MAX_PIXELS}"
                ))
            })?;
        if !(1..=255).contains(&maxval) {
            return Err(MapError::Pgm(format!(
                "maxval {maxval}: only 8-bit images (maxval 1..255)"
            )));
        }
        let pixels = if binary {
            // Exactly one whitespace byte separates the header from the raster.
            let s = pos + 1;
            let raster = bytes.get(s..s + count).ok_or_else(|| {
                MapError::Pgm(format!(
                    "raster has {} bytes, expected {count}",
                    bytes.len().saturating_sub(s)
                ))
            })?;
            raster.to_vec()
        } else {
            let mut px = Vec::with_capacity(count);
            for k in 0..count {
                let t = next_token(&mut pos).ok_or_else(|| {
                    MapError::Pgm(format!("raster ends after {k} of {count} values"))
                })?;
                let v = t
                    .parse::<usize>()
                    .ok()
                    .filter(|&v| v <= maxval)
                    .ok_or_else(|| {
                        MapError::Pgm(format!(
                            "value {k} ({t:?}) is not a number within 0..={maxval}"
                        ))
                    })?;
                px.push(v as u8);
            }
            px
        };
        if let Some(k) = pixels.iter().position(|&v| usize::from(v) > maxval) {
            return Err(MapError::Pgm(format!("pixel {k} exceeds maxval {maxval}")));
        }
        Ok(Pgm {
            width,
            height,
            maxval: maxval as u8,
            pixels,
        })
    }
}

/// What the import makes of a map.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// The site's id and version.
    pub id: String,
    pub version: u64,
    /// Treat unknown cells as free (default: as obstacles).
    pub unknown_is_free: bool,
}

/// One rectangle of occupied cells: image columns [c0, c1), rows [r0, r1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellRect {
    pub c0: usize,
    pub c1: usize,
    pub r0: usize,
    pub r1: usize,
}

/// Whether pixel value `v` is an obstacle under the map's thresholds.
pub fn occupied(y: &MapYaml, maxval: u8, v: u8, unknown_is_free: bool) -> bool {
    let m = f64::from(maxval);
    let p = if y.negate {
        f64::from(v) / m
    } else {
        (m - f64::from(v)) / m
    };
    if p > y.occupied_thresh {
        true
    } else if p < y.free_thresh {
        false
    } else {
        !unknown_is_free
    }
}

/// Occupied cells as rectangles: each row's runs, merged downwards with an
/// identical run (same columns) of the next row. Every occupied cell lies in
/// exactly one rectangle.
pub fn occupied_rectangles(y: &MapYaml, pgm: &Pgm, unknown_is_free: bool) -> Vec<CellRect> {
    let mut done = Vec::new();
    let mut open: Vec<CellRect> = Vec::new();
    let mut next: Vec<CellRect> = Vec::new();
    for r in 0..pgm.height {
        let row = &pgm.pixels[r * pgm.width..(r + 1) * pgm.width];
        next.clear();
        let mut c = 0;
        let mut k = 0; // walks `open`, sorted by c0
        while c < pgm.width {
            if !occupied(y, pgm.maxval, row[c], unknown_is_free) {
                c += 1;
                continue;
            }
            let c0 = c;
            while c < pgm.width && occupied(y, pgm.maxval, row[c], unknown_is_free) {
                c += 1;
            }
            while k < open.len() && open[k].c0 < c0 {
                done.push(open[k]);
                k += 1;
            }
            if k < open.len() && open[k].c0 == c0 && open[k].c1 == c {
                next.push(CellRect {
                    r1: r + 1,
                    ..open[k]
                });
                k += 1;
            } else {
                next.push(CellRect {
                    c0,
                    c1: c,
                    r0: r,
                    r1: r + 1,
                });
            }
        }
        done.extend_from_slice(&open[k..]);
        std::mem::swap(&mut open, &mut next);
    }
    done.extend_from_slice(&open);
    done
}

/// The map as a site file: the image's extent as bounds, each rectangle of
/// occupied cells an obstacle polygon `map-R-C` (R, C: its top-left pixel).
pub fn to_site_file(y: &MapYaml, pgm: &Pgm, opts: &ImportOptions) -> Result<SiteFile, MapError> {
    let rects = occupied_rectangles(y, pgm, opts.unknown_is_free);
    if rects.len() > MAX_FEATURES {
        return Err(MapError::TooManyFeatures {
            found: rects.len(),
            limit: MAX_FEATURES,
        });
    }
    let (s, c) = y.origin[2].sin_cos();
    let res = y.resolution;
    let h = pgm.height;
    // Map frame (x right, y up from the lower-left pixel) to world.
    let world = |mx: f64, my: f64| [y.origin[0] + c * mx - s * my, y.origin[1] + s * mx + c * my];
    let rect = |x0: f64, x1: f64, y0: f64, y1: f64| {
        vec![world(x0, y0), world(x1, y0), world(x1, y1), world(x0, y1)]
    };
    let obstacles = rects
        .iter()
        .map(|r| ObstacleEntry {
            id: format!("map-{}-{}", r.r0, r.c0),
            polygon: Some(rect(
                r.c0 as f64 * res,
                r.c1 as f64 * res,
                (h - r.r1) as f64 * res,
                (h - r.r0) as f64 * res,
            )),
            ..Default::default()
        })
        .collect();
    Ok(SiteFile {
        format: FORMAT.to_string(),
        id: opts.id.clone(),
        version: opts.version,
        bounds: rect(0.0, pgm.width as f64 * res, 0.0, h as f64 * res),
        obstacles,
        keepout: Vec::new(),
    })
}

/// YAML text and image bytes to a validated site; its content hash is over
/// the YAML's bytes, then the image's.
pub fn import(yaml_text: &str, pgm_bytes: &[u8], opts: &ImportOptions) -> Result<Site, MapError> {
    let y = MapYaml::parse(yaml_text)?;
    let pgm = Pgm::parse(pgm_bytes)?;
    let file = to_site_file(&y, &pgm, opts)?;
    let hash = content_hash_extend(content_hash(yaml_text.as_bytes()), pgm_bytes);
    Ok(Site::from_file(file, hash)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{FeatureKind, SiteIndex};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const YAML: &str = "image: pit.pgm  # the map\nresolution: 0.5\norigin: [-2.0, 1.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n";

    fn opts() -> ImportOptions {
        ImportOptions {
            id: "imported".into(),
            version: 1,
            unknown_is_free: false,
        }
    }

    #[test]
    fn yaml_keys_and_errors_name_the_line() {
        let y = MapYaml::parse(YAML).unwrap();
        assert_eq!(y.image, "pit.pgm");
        assert_eq!(y.origin, [-2.0, 1.0, 0.0]);
        assert_eq!(y.mode, MapMode::Trinary);
        let e = MapYaml::parse(&YAML.replace("negate: 0", "negate: 0\noccupied_tresh: 0.6"))
            .unwrap_err();
        assert_eq!(
            e,
            MapError::Yaml {
                line: 5,
                message: "unknown key `occupied_tresh`".into()
            }
        );
        let e = MapYaml::parse(&YAML.replace("resolution: 0.5\n", "")).unwrap_err();
        assert_eq!(e, MapError::MissingKey("resolution"));
        let e = MapYaml::parse(&YAML.replace("[-2.0, 1.0, 0.0]", "[-2.0, 1.0]")).unwrap_err();
        assert!(matches!(e, MapError::Yaml { line: 3, .. }), "{e}");
        assert!(MapYaml::parse(&format!("{YAML}mode: raw\n")).is_err());
        assert!(MapYaml::parse(&YAML.replace("0.196", "0.7")).is_err());
        assert!(
            MapYaml::parse(&YAML.replace("image: pit.pgm", "image: \"my map.pgm\""))
                .unwrap()
                .image
                == "my map.pgm"
        );
    }

    #[test]
    fn p2_and_p5_read_the_same_image() {
        let p2 = b"P2\n# made by hand\n3 2\n255\n0 255 10\n205 254 0\n";
        let mut p5 = b"P5\n3 2\n255\n".to_vec();
        p5.extend_from_slice(&[0, 255, 10, 205, 254, 0]);
        let a = Pgm::parse(p2).unwrap();
        let b = Pgm::parse(&p5).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.pixels, vec![0, 255, 10, 205, 254, 0]);
        assert!(Pgm::parse(b"P5\n3 2\n255\n\x00\x01").is_err());
        assert!(Pgm::parse(b"P5\n3 2\n65535\n").is_err());
        assert!(Pgm::parse(b"P6\n3 2\n255\n").is_err());
        assert!(Pgm::parse(b"P2\n2 1\n9\n3 10\n").is_err());
    }

    fn random_image(rng: &mut ChaCha8Rng, w: usize, h: usize) -> Pgm {
        // Blobs: mostly free, occupied patches, a few unknown (205).
        let mut pixels = vec![254u8; w * h];
        for _ in 0..(w * h / 20) {
            let (c, r) = (rng.gen_range(0..w), rng.gen_range(0..h));
            let v = if rng.gen_bool(0.8) { 0 } else { 205 };
            for dr in 0..rng.gen_range(1..4) {
                for dc in 0..rng.gen_range(1..5) {
                    if r + dr < h && c + dc < w {
                        pixels[(r + dr) * w + c + dc] = v;
                    }
                }
            }
        }
        Pgm {
            width: w,
            height: h,
            maxval: 255,
            pixels,
        }
    }

    #[test]
    fn rectangles_cover_exactly_the_occupied_cells() {
        let y = MapYaml::parse(YAML).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for unknown_is_free in [false, true] {
            let pgm = random_image(&mut rng, 37, 23);
            let rects = occupied_rectangles(&y, &pgm, unknown_is_free);
            let mut count = vec![0u8; pgm.width * pgm.height];
            for r in &rects {
                for row in r.r0..r.r1 {
                    for col in r.c0..r.c1 {
                        count[row * pgm.width + col] += 1;
                    }
                }
            }
            for (k, &v) in pgm.pixels.iter().enumerate() {
                let occ = occupied(&y, 255, v, unknown_is_free);
                assert_eq!(count[k], u8::from(occ), "pixel {k}");
            }
            // Merging across rows happened (fewer rectangles than row runs).
            assert!(rects.iter().any(|r| r.r1 - r.r0 > 1));
        }
    }

    #[test]
    fn imported_site_places_cells_in_the_pose_frame_with_origin_and_yaw() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let pgm = random_image(&mut rng, 30, 20);
        let mut p5 = format!("P5\n{} {}\n255\n", pgm.width, pgm.height).into_bytes();
        p5.extend_from_slice(&pgm.pixels);
        let yaw = 0.4f64;
        let yaml = YAML.replace("[-2.0, 1.0, 0.0]", &format!("[-2.0, 1.0, {yaw}]"));
        let site = import(&yaml, &p5, &opts()).unwrap();
        assert!(site
            .features()
            .iter()
            .all(|f| f.kind == FeatureKind::Obstacle));
        let idx = SiteIndex::new(site);
        let y = MapYaml::parse(&yaml).unwrap();
        // Each pixel's centre, mapped independently to the world, is inside
        // some feature exactly when the pixel is occupied.
        let (s, c) = yaw.sin_cos();
        for row in 0..pgm.height {
            for col in 0..pgm.width {
                let mx = (col as f64 + 0.5) * 0.5;
                let my = ((pgm.height - 1 - row) as f64 + 0.5) * 0.5;
                let p = [-2.0 + c * mx - s * my, 1.0 + s * mx + c * my];
                let mut out = [crate::site::Near::default(); 1];
                let n = idx.nearest(p, 0.0, &mut out);
                let occ = occupied(&y, 255, pgm.pixels[row * pgm.width + col], false);
                assert_eq!(
                    n == 1 && out[0].nearest.distance < 0.0,
                    occ,
                    "pixel ({row}, {col})"
                );
            }
        }
        // Hash covers both files.
        let other = import(&yaml.replace("0.5\n", "0.5 \n"), &p5, &opts()).unwrap();
        assert_ne!(other.hash(), idx.site().hash());
    }
}
