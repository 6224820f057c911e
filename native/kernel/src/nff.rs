//! Parser for Eric Haines' Neutral File Format (NFF, see `NFF.TXT` of the SPD).
//!
//! Entities: `v` (from/at/up/angle/hither/resolution), `b`, `l x y z [r g b]`,
//! `f r g b Kd Ks Shine T ior`, `c` (cone/cylinder: base + radius, apex + radius),
//! `s x y z r`, `p n` + n vertices, `pp n` + n (vertex, normal) pairs, and `#` comments.
//! The file is read as a stream of whitespace-separated tokens, so an entity may span lines
//! (the polygon vertices follow on the next lines) or share one (`c` on one line).
//!
//! Conventions chosen where the format leaves freedom (SPD Readme, "relative intensity"):
//! - a light without a colour has intensity `sqrt(n) / (2 n)` for `n` lights, in all channels;
//! - the ambient term is that same value times the surface colour and Kd (ambient light is
//!   reflected diffusely; so a clear glass with Kd 0.1 does not glow at every interface);
//! - colours are display values, as the SPD's own pictures show them ([`Scene::display_referred`]);
//! - a polygon with 3 vertices becomes a triangle; a simple one of up to 1024 (also concave,
//!   e.g. the 144-gons of `gears`) is ear-clipped into triangles; any other (larger, or one
//!   ear clipping gives up on, as on most self-intersecting ones) is tested with the even-odd
//!   crossing rule, in O(log n) per ray ([`crate::polygon`]); degenerate (zero-area) ones
//!   are left out, with a warning;
//! - a `pp` patch is triangulated as a fan (SPD patches are always triangles) with its vertex
//!   normals interpolated for smooth shading;
//! - negative radii (both, for cones) make the object visible only from the inside;
//! - `hither` is read (it must be a number) and not used: a ray tracer needs no near plane;
//! - a `v` without `resolution` renders at 512x512.
//!
//! Nothing is dropped or overridden silently (docs/scene-format.md has the table). Errors,
//! which stop the parse: a second `v` or `b` (the scene has one of each), a keyword given twice
//! inside `v`, an `angle` outside (0, 180), cone radii of opposite signs, a transparent `f`
//! (T > 0) with an index of refraction <= 0, and a token longer than
//! [`limits::MAX_TOKEN_BYTES`]. Warnings, with file and line, on the scene
//! ([`Scene::warnings`]): a zero-radius sphere, a degenerate cone, polygon or patch (left
//! out), a zero patch normal, an `f` that no object uses, colours, Kd, Ks or T outside [0, 1],
//! Ks + T > 1, a negative Phong exponent, negative light or background colours, and a scene
//! without objects or lights.
//!
//! Errors carry the line: `balls.nff:12: polygon needs at least 3 vertices, got 2`. Numbers
//! that are NaN or infinite (also after conversion to f32) are rejected.

use crate::camera::Camera;
use crate::error::snippet_bytes;
use crate::light::{spd_intensity, Light};
use crate::limits;
use crate::material::{check_light_colour, Material};
use crate::scene::{Scene, SceneBuilder};
use crate::Error;
use glam::Vec3A;

struct Lexer<'a> {
    src: &'a [u8],
    pos: usize,
    line: usize,
    file: &'a str,
}

impl<'a> Lexer<'a> {
    /// Next token and its line, or `None` at the end. A token longer than
    /// [`limits::MAX_TOKEN_BYTES`] is an error (found by the scan, before it is looked at).
    fn next(&mut self) -> Result<Option<(&'a [u8], usize)>, Error> {
        let s = self.src;
        loop {
            let Some(&c) = s.get(self.pos) else {
                return Ok(None);
            };
            match c {
                b'\n' => {
                    self.line += 1;
                    self.pos += 1;
                }
                b'#' => {
                    while self.pos < s.len() && s[self.pos] != b'\n' {
                        self.pos += 1;
                    }
                }
                c if c.is_ascii_whitespace() => self.pos += 1,
                _ => break,
            }
        }
        let start = self.pos;
        while self.pos < s.len() && !s[self.pos].is_ascii_whitespace() && s[self.pos] != b'#' {
            self.pos += 1;
        }
        let len = self.pos - start;
        limits::check_token(len as u64).map_err(|e| self.err(self.line, e.to_string()))?;
        Ok(Some((&s[start..self.pos], self.line)))
    }

    fn peek(&mut self) -> Result<Option<&'a [u8]>, Error> {
        let (pos, line) = (self.pos, self.line);
        let t = self.next()?.map(|t| t.0);
        self.pos = pos;
        self.line = line;
        Ok(t)
    }

    fn err(&self, line: usize, msg: impl Into<String>) -> Error {
        Error::parse(self.file, line, msg)
    }

    fn number(&mut self, what: &str, entity_line: usize) -> Result<f32, Error> {
        let Some((tok, line)) = self.next()? else {
            return Err(self.err(entity_line, format!("file ended in the middle of {what}")));
        };
        if let Some(v) = std::str::from_utf8(tok)
            .ok()
            .and_then(|t| t.parse::<f32>().ok())
            .filter(|v| v.is_finite())
        {
            return Ok(v);
        }
        let text = String::from_utf8_lossy(tok);
        let shown = snippet_bytes(tok);
        match text.parse::<f32>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(self.err(line, format!("number '{shown}' in {what} is not finite"))),
            Err(_) => Err(self.err(line, format!("expected a number in {what}, got '{shown}'"))),
        }
    }

    fn vec3(&mut self, what: &str, entity_line: usize) -> Result<Vec3A, Error> {
        Ok(Vec3A::new(
            self.number(what, entity_line)?,
            self.number(what, entity_line)?,
            self.number(what, entity_line)?,
        ))
    }

    fn integer(&mut self, what: &str, entity_line: usize) -> Result<(u64, usize), Error> {
        let Some((tok, line)) = self.next()? else {
            return Err(self.err(entity_line, format!("file ended in the middle of {what}")));
        };
        let text = String::from_utf8_lossy(tok);
        match text.parse::<u64>() {
            Ok(v) => Ok((v, line)),
            Err(_) => Err(self.err(
                line,
                format!(
                    "expected a non-negative integer for {what}, got '{}'",
                    snippet_bytes(tok)
                ),
            )),
        }
    }

    /// Whether the token that ends at the current position is the first one on its line.
    fn token_starts_line(&self, tok: &[u8]) -> bool {
        let start = self.pos.saturating_sub(tok.len());
        let before = self.src.get(..start).unwrap_or_default();
        before
            .iter()
            .rev()
            .take_while(|&&c| c != b'\n')
            .all(|c| c.is_ascii_whitespace())
    }
}

/// Whether a token could be meant as an NFF keyword: an ASCII letter, then at most 15 ASCII
/// letters, digits or underscores. Only such a token is echoed in the "unknown entity" error,
/// so that a file that is not a scene (`/etc/passwd`) does not have its content printed.
fn looks_like_keyword(tok: &[u8]) -> bool {
    matches!(tok.first(), Some(c) if c.is_ascii_alphabetic())
        && tok.len() <= 16
        && tok.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

const ENTITIES: &str = "v, b, l, f, c, s, p, pp or #";

fn is_number(tok: &[u8]) -> bool {
    matches!(tok.first(), Some(c) if c.is_ascii_digit() || *c == b'-' || *c == b'+' || *c == b'.')
}

/// Names of the `f` values in warnings.
const FILL_NAMES: [&str; 5] = ["Kd", "Ks", "Shine", "T", "index of refraction"];

/// Parses NFF bytes into a scene. What parses but may not render as meant becomes a warning of
/// the scene ([`Scene::warnings`]); see the module docs.
pub fn parse(bytes: &[u8], file: &str) -> Result<Scene, Error> {
    let mut b = SceneBuilder::new();
    b.display_referred = true;
    read(bytes, file, &mut b, Role::Scene)?;
    crate::warning::scene_warnings(&mut b, file);
    b.build(file)
}

/// Adds the objects of an NFF file (and its lights when `lights`) to a scene being built from
/// another file (a TOML scene's `include`): its view `v` and background `b` are read, checked
/// and left out, and it need not have a view. Its lights without a colour get the SPD's
/// intensity for the file's own light count, as when it is rendered alone.
pub(crate) fn include(
    bytes: &[u8],
    file: &str,
    b: &mut SceneBuilder,
    lights: bool,
) -> Result<(), Error> {
    read(bytes, file, b, Role::Include { lights })
}

/// What an NFF file is to the scene it is read into.
#[derive(Clone, Copy, PartialEq)]
enum Role {
    /// The scene itself: view, background and lights are the scene's.
    Scene,
    /// Objects added to another file's scene, with its lights or without them.
    Include { lights: bool },
}

fn read(bytes: &[u8], file: &str, b: &mut SceneBuilder, role: Role) -> Result<(), Error> {
    let material = b.material(Material::default());
    let mut r = Reader {
        lx: Lexer {
            src: bytes,
            pos: 0,
            line: 1,
            file,
        },
        b,
        include: role != Role::Scene,
        keep_lights: matches!(role, Role::Scene | Role::Include { lights: true }),
        file_lights: 0,
        material,
        colourless_lights: Vec::new(),
        verts: Vec::new(),
        normals: Vec::new(),
        view_line: None,
        background_line: None,
        unused_fill: None,
    };
    let mut last_line = 1;
    while let Some((tok, line)) = r.lx.next()? {
        last_line = line;
        match tok {
            b"v" => r.view(line)?,
            b"b" => r.background(line)?,
            b"l" => r.light(line)?,
            b"f" => r.fill(line)?,
            b"s" => r.sphere(line)?,
            b"c" => r.cone(line)?,
            b"p" | b"pp" => r.polygon(tok == b"pp", line)?,
            _ => return Err(r.unknown(tok, line)),
        }
    }
    r.finish(last_line)
}

/// The state of reading one NFF file into a scene builder.
struct Reader<'a, 'b> {
    lx: Lexer<'a>,
    b: &'b mut SceneBuilder,
    /// The file is included in another's scene: its view and background are left out.
    include: bool,
    /// Its lights are the scene's.
    keep_lights: bool,
    /// Lights in the file (kept or not), for the SPD's intensity.
    file_lights: usize,
    /// The material of the last `f`.
    material: u32,
    /// The scene's lights the file gave no colour.
    colourless_lights: Vec<usize>,
    /// The vertices and normals of the polygon or patch being read.
    verts: Vec<Vec3A>,
    normals: Vec<Vec3A>,
    /// Lines of the `v` and `b` seen (each sets a single value: a second would replace it).
    view_line: Option<usize>,
    background_line: Option<usize>,
    /// The line of the last `f`, while no object has used it yet.
    unused_fill: Option<usize>,
}

impl Reader<'_, '_> {
    /// Adds warning `w` at `line`.
    fn warn(&mut self, line: usize, w: impl FnOnce() -> String) {
        self.b.warnings.add(self.lx.file, Some(line), w);
    }

    /// A builder's error (a limit, the memory left) as an error at `line`.
    fn at(&self, line: usize) -> impl Fn(Error) -> Error + '_ {
        move |e| self.lx.err(line, e.to_string())
    }

    /// The viewpoint `v`.
    fn view(&mut self, line: usize) -> Result<(), Error> {
        if let Some(first) = self.view_line {
            return Err(self.lx.err(
                line,
                format!(
                    "second viewpoint 'v' (the first is at line {first}): a scene has one \
                     view, and this one would replace it"
                ),
            ));
        }
        self.view_line = Some(line);
        if self.include {
            parse_view(&mut self.lx, &mut SceneBuilder::new(), line)
        } else {
            parse_view(&mut self.lx, self.b, line)
        }
    }

    /// The background colour `b`.
    fn background(&mut self, line: usize) -> Result<(), Error> {
        if let Some(first) = self.background_line {
            return Err(self.lx.err(
                line,
                format!(
                    "second background colour 'b' (the first is at line {first}): a \
                     scene has one, and this one would replace it"
                ),
            ));
        }
        self.background_line = Some(line);
        let background = self.lx.vec3("background colour 'b'", line)?;
        if !self.include {
            self.b.background = background;
            if let Some(w) = check_light_colour("background colour", background) {
                self.warn(line, || w);
            }
        }
        Ok(())
    }

    /// A light `l`, with or without a colour.
    fn light(&mut self, line: usize) -> Result<(), Error> {
        let position = self.lx.vec3("light 'l'", line)?;
        limits::check(
            "light count",
            self.b.lights.len() as u64 + 1,
            limits::MAX_LIGHTS as u64,
            "MAX_LIGHTS",
        )
        .map_err(self.at(line))?;
        self.file_lights += 1;
        let color = if self.lx.peek()?.is_some_and(is_number) {
            let c = self.lx.vec3("light colour", line)?;
            if let Some(w) = check_light_colour("light colour", c).filter(|_| self.keep_lights) {
                self.warn(line, || w);
            }
            c
        } else {
            if self.keep_lights {
                self.colourless_lights.push(self.b.lights.len());
            }
            Vec3A::ZERO
        };
        if self.keep_lights {
            self.b.lights.push(Light { position, color });
        }
        Ok(())
    }

    /// A fill colour `f`: the material of the objects that follow.
    fn fill(&mut self, line: usize) -> Result<(), Error> {
        let what = "fill colour 'f'";
        let lx = &mut self.lx;
        let color = lx.vec3(what, line)?;
        let m = Material {
            color,
            kd: lx.number(what, line)?,
            ks: lx.number(what, line)?,
            shine: lx.number(what, line)?,
            t: lx.number(what, line)?,
            ior: lx.number(what, line)?,
            checker: None,
        };
        for w in m.check(FILL_NAMES).map_err(|e| self.lx.err(line, e))? {
            self.warn(line, || format!("fill colour 'f': {w}"));
        }
        if let Some(unused) = self.unused_fill.replace(line) {
            self.warn(unused, || {
                format!(
                    "fill colour 'f' is used by no object: the 'f' at line {line} \
                     replaces it first"
                )
            });
        }
        self.material = self.b.material(m);
        Ok(())
    }

    /// A sphere `s`.
    fn sphere(&mut self, line: usize) -> Result<(), Error> {
        let c = self.lx.vec3("sphere 's'", line)?;
        let r = self.lx.number("sphere 's'", line)?;
        self.unused_fill = None;
        let before = self.b.primitive_count();
        self.b
            .sphere(c, r, self.material)
            .map_err(|e| self.lx.err(line, e.to_string()))?;
        if self.b.primitive_count() == before {
            self.warn(line, || {
                "sphere 's' has radius 0 and is not rendered".into()
            });
        }
        Ok(())
    }

    /// A cone or cylinder `c`.
    fn cone(&mut self, line: usize) -> Result<(), Error> {
        let what = "cone/cylinder 'c'";
        let lx = &mut self.lx;
        let base = lx.vec3(what, line)?;
        let r0 = lx.number(what, line)?;
        let apex = lx.vec3(what, line)?;
        let r1 = lx.number(what, line)?;
        check_cone_radii(r0, r1).map_err(|e| lx.err(line, format!("{what}: {e}")))?;
        self.unused_fill = None;
        let before = self.b.primitive_count();
        self.b
            .cone(base, r0, apex, r1, self.material)
            .map_err(|e| self.lx.err(line, e.to_string()))?;
        if self.b.primitive_count() == before {
            self.warn(line, || {
                format!("{what} has a zero-length axis or both radii 0 and is not rendered")
            });
        }
        Ok(())
    }

    /// A polygon `p`, or with `patch` a polygonal patch `pp` (vertex normals, fanned into
    /// triangles).
    fn polygon(&mut self, patch: bool, line: usize) -> Result<(), Error> {
        let what = if patch { "patch 'pp'" } else { "polygon 'p'" };
        let (n, nline) = self
            .lx
            .integer(&format!("the vertex count of {what}"), line)?;
        if n < 3 {
            let kind = if patch { "patch" } else { "polygon" };
            return Err(self
                .lx
                .err(nline, format!("{kind} needs at least 3 vertices, got {n}")));
        }
        // checked before reading (and storing) any vertex
        limits::check(
            format!("the vertex count of {what}"),
            n,
            limits::MAX_POLYGON_VERTICES as u64,
            "MAX_POLYGON_VERTICES",
        )
        .map_err(self.at(nline))?;
        self.verts.clear();
        self.normals.clear();
        for _ in 0..n {
            self.verts.push(self.lx.vec3(what, line)?);
            if patch {
                self.normals.push(self.lx.vec3(what, line)?);
            }
        }
        self.unused_fill = None;
        let before = self.b.primitive_count();
        let r = if patch {
            self.patch(what, line)
        } else {
            self.b.polygon(&self.verts, self.material)
        };
        r.map_err(|e| self.lx.err(line, e.to_string()))?;
        if self.b.primitive_count() == before {
            self.warn(line, || {
                format!(
                    "{what} has zero area (its vertices are equal or on one line) and is \
                     not rendered"
                )
            });
        }
        Ok(())
    }

    /// The patch read into `verts` and `normals`, as a fan of smooth triangles.
    fn patch(&mut self, what: &str, line: usize) -> Result<(), Error> {
        let (verts, normals) = (&self.verts, &self.normals);
        if normals.contains(&Vec3A::ZERO) {
            self.b.warnings.add(self.lx.file, Some(line), || {
                format!(
                    "{what} has a zero vertex normal, which has no direction: the \
                     shading there follows the other vertices' normals"
                )
            });
        }
        for i in 1..verts.len() - 1 {
            self.b.triangle(
                [verts[0], verts[i], verts[i + 1]],
                Some([normals[0], normals[i], normals[i + 1]]),
                self.material,
            )?;
        }
        Ok(())
    }

    /// The error for token `tok` where an entity should start.
    fn unknown(&self, tok: &[u8], line: usize) -> Error {
        let message = if looks_like_keyword(tok) {
            format!(
                "unknown entity '{}' (expected {ENTITIES})",
                String::from_utf8_lossy(tok)
            )
        } else if self.lx.token_starts_line(tok) {
            format!("line does not start with an NFF entity ({ENTITIES}); is this an NFF file?")
        } else {
            format!(
                "unexpected text where an NFF entity ({ENTITIES}) should start \
                 (too many values for the entity before it?)"
            )
        };
        self.lx.err(line, message)
    }

    /// The checks at the end of the file (`last_line`), and the colour of its lights without
    /// one.
    fn finish(mut self, last_line: usize) -> Result<(), Error> {
        if self.b.camera.is_none() && !self.include {
            return Err(self
                .lx
                .err(last_line, "no viewpoint: the file has no 'v' entity"));
        }
        if let Some(unused) = self.unused_fill {
            self.warn(unused, || {
                "fill colour 'f' is used by no object: none follows it".into()
            });
        }
        let intensity = spd_intensity(self.file_lights);
        for i in self.colourless_lights {
            if let Some(l) = self.b.lights.get_mut(i) {
                l.color = Vec3A::splat(intensity);
            }
        }
        Ok(())
    }
}

/// A cone's radii must not have opposite signs: NFF.TXT makes a cone with negative radii an
/// "inside" object (seen from inside only), and positive ones are seen from outside; one of each
/// means neither (a zero radius goes with either). TOML cones follow the same rule.
pub(crate) fn check_cone_radii(r0: f32, r1: f32) -> Result<(), String> {
    if (r0 < 0.0 && r1 > 0.0) || (r0 > 0.0 && r1 < 0.0) {
        Err(format!(
            "radii {r0} and {r1} have opposite signs (both negative: seen from inside only; both \
             positive: from outside)"
        ))
    } else {
        Ok(())
    }
}

fn parse_view(lx: &mut Lexer, b: &mut SceneBuilder, line: usize) -> Result<(), Error> {
    let (mut from, mut at, mut up, mut angle) = (None, None, None, None);
    let mut resolution = (512u32, 512u32);
    // the line where each keyword was given, to refuse a second one
    let mut seen: Vec<(&[u8], usize)> = Vec::new();
    while let Some(tok) = lx.peek()? {
        let what = match tok {
            b"from" | b"at" | b"up" | b"angle" | b"hither" | b"resolution" => tok,
            _ => break,
        };
        let Some((_, kline)) = lx.next()? else { break };
        if let Some((_, first)) = seen.iter().find(|(k, _)| *k == what) {
            return Err(lx.err(
                kline,
                format!(
                    "'{}' given twice in the viewpoint 'v' (first at line {first})",
                    String::from_utf8_lossy(what)
                ),
            ));
        }
        seen.push((what, kline));
        match what {
            b"from" => from = Some(lx.vec3("'from'", kline)?),
            b"at" => at = Some(lx.vec3("'at'", kline)?),
            b"up" => up = Some(lx.vec3("'up'", kline)?),
            b"angle" => angle = Some(lx.number("'angle'", kline)?),
            b"hither" => {
                lx.number("'hither'", kline)?;
            }
            _ => {
                let (w, _) = lx.integer("'resolution'", kline)?;
                let (h, hline) = lx.integer("'resolution'", kline)?;
                // u64 as read, so nothing is truncated before the check
                limits::check_resolution(w, h).map_err(|e| lx.err(hline, e.to_string()))?;
                resolution = (w as u32, h as u32);
            }
        }
    }
    let missing = |n: &str| lx.err(line, format!("viewpoint 'v' lacks '{n}'"));
    let from = from.ok_or_else(|| missing("from"))?;
    let at = at.ok_or_else(|| missing("at"))?;
    let up = up.ok_or_else(|| missing("up"))?;
    let angle = angle.ok_or_else(|| missing("angle"))?;
    if !(angle > 0.0 && angle < 180.0) {
        return Err(lx.err(
            line,
            format!("viewpoint 'angle' {angle} is not in (0, 180) degrees"),
        ));
    }
    b.camera = Some(Camera::new(from, at, up, angle).ok_or_else(|| {
        lx.err(
            line,
            "degenerate view: 'from' equals 'at', or 'up' is parallel to the view direction",
        )
    })?);
    b.resolution = resolution;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 8 6\n";

    fn err(src: &str) -> String {
        match parse(src.as_bytes(), "t.nff") {
            Ok(_) => panic!("expected an error for {src:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn parses_all_entities() {
        let src = format!(
            "{HEAD}b 0.1 0.2 0.3\nl 1 2 3\nl 4 5 6 1 0.5 0.25\n# comment\nf 1 0 0 1 0 1 0 1\n\
             s 0 0 0 1 # trailing comment\np 3\n0 0 0\n1 0 0\n0 1 0\np 4 0 0 1 1 0 1 1 1 1 0 1 1\n\
             pp 3\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\nc 0 0 0 1 0 0 1 1\n"
        );
        let s = parse(src.as_bytes(), "t.nff").unwrap();
        assert_eq!(s.resolution(), (8, 6));
        assert_eq!(s.light_count(), 2);
        assert_eq!(s.primitive_count(), 5);
        let i = spd_intensity(2);
        assert_eq!(s.lights[0].color, Vec3A::splat(i));
        assert_eq!(s.lights[1].color, Vec3A::new(1.0, 0.5, 0.25));
        assert_eq!(s.background, Vec3A::new(0.1, 0.2, 0.3));
    }

    #[test]
    fn line_numbered_errors() {
        assert_eq!(
            err(&format!("{HEAD}\np 2\n0 0 0\n1 1 1\n")),
            "t.nff:9: polygon needs at least 3 vertices, got 2"
        );
        assert_eq!(
            err(&format!("{HEAD}s 0 0 x 1\n")),
            "t.nff:8: expected a number in sphere 's', got 'x'"
        );
        assert_eq!(
            err(&format!("{HEAD}s 0 0 0\n")),
            "t.nff:8: file ended in the middle of sphere 's'"
        );
        assert_eq!(
            err(&format!("{HEAD}\n\nq 1 2\n")),
            "t.nff:10: unknown entity 'q' (expected v, b, l, f, c, s, p, pp or #)"
        );
        assert_eq!(
            err(&format!("{HEAD}s 0 0 nan 1\n")),
            "t.nff:8: number 'nan' in sphere 's' is not finite"
        );
        assert_eq!(
            err(&format!("{HEAD}s 0 0 1e39 1\n")),
            "t.nff:8: number '1e39' in sphere 's' is not finite"
        );
        assert_eq!(
            err("v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nresolution 100000 10\n"),
            "t.nff:6: image width is 100000 pixels, more than the limit of 16384 \
             (limits::MAX_SIDE); render in tiles or raise the constant in \
             native/kernel/src/limits.rs"
        );
        assert!(
            err("v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nresolution 16384 16384\n")
                .starts_with(
                    "t.nff:6: resolution 16384x16384 is 268435456 pixels, more than the limit \
                     of 67108864 (limits::MAX_PIXELS)"
                )
        );
        assert!(err(&format!("{HEAD}p 99999999999\n")).starts_with(
            "t.nff:8: the vertex count of polygon 'p' is 99999999999, more than the limit of \
             1048576 (limits::MAX_POLYGON_VERTICES); raise the constant"
        ));
        assert_eq!(
            err("s 0 0 0 1\n"),
            "t.nff:1: no viewpoint: the file has no 'v' entity"
        );
        assert!(err("v\nfrom 0 0 0\nat 0 0 0\nup 0 1 0\nangle 45\n")
            .starts_with("t.nff:1: degenerate view"));
        assert_eq!(
            err(&format!("{HEAD}p 3\n0 0 0\n1 0 0\n")),
            "t.nff:8: file ended in the middle of polygon 'p'"
        );
        assert_eq!(
            err(&format!("{HEAD}p -3\n")),
            "t.nff:8: expected a non-negative integer for the vertex count of polygon 'p', got '-3'"
        );
    }

    #[test]
    fn errors_do_not_echo_what_is_not_a_scene() {
        let e = err("root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin:/bin/false\n");
        assert!(!e.contains("root:"), "{e}");
        assert_eq!(
            e,
            "t.nff:1: line does not start with an NFF entity (v, b, l, f, c, s, p, pp or #); \
             is this an NFF file?"
        );
        let e = err(&format!("{HEAD}s 0 0 0 1 secret_number_42x\n"));
        assert_eq!(
            e,
            "t.nff:8: unexpected text where an NFF entity (v, b, l, f, c, s, p, pp or #) should \
             start (too many values for the entity before it?)"
        );
        // a keyword-like token is still named
        assert!(err("hello 1 2\n").contains("unknown entity 'hello'"));
        assert!(!err("seventeen_letters 1\n").contains("seventeen"));
        // control characters are escaped
        let e = err(&format!("{HEAD}s 0 0 \x1b[31m 1\n"));
        assert_eq!(
            e,
            "t.nff:8: expected a number in sphere 's', got '\\u{1b}[31m'"
        );
        assert!(!e.contains('\x1b'));
        // a huge single token gives a short error, in every place a token is echoed
        let big = "a".repeat(10 << 20);
        for src in [
            big.clone(),
            format!("{HEAD}s 0 0 {big} 1\n"),
            format!("{HEAD}s 0 0 1{} 1\n", "0".repeat(10 << 20)),
            format!("{HEAD}p 9{big}\n"),
        ] {
            let e = err(&src);
            assert!(
                e.len() < 300,
                "{} bytes: {}",
                e.len(),
                &e[..300.min(e.len())]
            );
        }
    }

    #[test]
    fn never_panics_on_garbage() {
        let inputs: [&[u8]; 6] = [
            b"",
            b"\xff\xfe v",
            b"v from",
            b"pp 3 1 2 3",
            b"l 1 2 3 4",
            b"#\n#\n",
        ];
        for i in inputs {
            let _ = parse(i, "g.nff");
        }
    }
}
