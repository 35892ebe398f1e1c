//! The one PLY reader and writer of the workspace (ascii and binary little-endian point clouds),
//! used by the simulator's `ply` command, the server's offline `detect --points` and the CLI's
//! `landing detect FILE.ply`.
//!
//! Only the `vertex` element is kept: its `x`, `y`, `z` properties (any scalar type, usually
//! `float` or `double`) and an optional per-point class from a `class` or `label` property of an
//! integer type (values 0..=255, `landing.v1.SemanticClass` numbers). Every other property
//! and every other element is parsed and skipped, list properties included. Big-endian files are
//! rejected with a clear message rather than misread. Errors ([`PlyError`]) name the header line,
//! or the element, row and property, that is wrong.
//!
//! ```
//! let text = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
//! property float z\nproperty uchar class\nend_header\n0 0 1 4\n1 0 1 4\n";
//! let cloud = landing_recording::ply::parse(text).unwrap();
//! assert_eq!(cloud.points, vec![[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]]);
//! assert_eq!(cloud.classes, Some(vec![4, 4]));
//! ```

use std::path::Path;

/// Why a PLY file could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlyError {
    /// The file could not be read.
    #[error("cannot read `{path}`: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A header line is malformed or unsupported (`line` counts from 1; 0 for the header as a
    /// whole).
    #[error("PLY header, line {line}: {reason}")]
    Header { line: usize, reason: String },
    /// The vertex element lacks a required property.
    #[error("PLY element `{element}` has no property `{property}`")]
    MissingProperty { element: String, property: String },
    /// A property has a type this reader cannot use for its role.
    #[error("PLY element `{element}`, property `{property}`: {reason}")]
    UnsupportedProperty {
        element: String,
        property: String,
        reason: String,
    },
    /// Body data is malformed or truncated (`index` is the row within `element`).
    #[error("PLY data, {element} {index}, property `{property}`: {reason}")]
    Data {
        element: String,
        index: usize,
        property: String,
        reason: String,
    },
}

/// The points of a PLY file, with their classes when the file has them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlyCloud {
    /// x, y, z of every vertex, in file order.
    pub points: Vec<[f32; 3]>,
    /// One class per point, from a `class` or `label` property.
    pub classes: Option<Vec<u8>>,
}

/// Reads and parses the PLY file at `path`.
pub fn read(path: &Path) -> Result<PlyCloud, PlyError> {
    let bytes = std::fs::read(path).map_err(|source| PlyError::Io {
        path: path.display().to_string(),
        source,
    })?;
    parse(&bytes)
}

/// Parses a whole PLY file held in memory.
pub fn parse(bytes: &[u8]) -> Result<PlyCloud, PlyError> {
    let (header, body) = parse_header(bytes)?;
    match header.format {
        Format::Ascii => read_ascii(&header, body),
        Format::BinaryLittleEndian => read_binary(&header, body),
    }
}

/// Writes `cloud` as a binary little-endian PLY (float x, y, z and, with classes, uchar class).
pub fn write_binary(cloud: &PlyCloud) -> Vec<u8> {
    write_binary_with_comment(cloud, None)
}

/// [`write_binary`] with an optional `comment` line in the header.
pub fn write_binary_with_comment(cloud: &PlyCloud, comment: Option<&str>) -> Vec<u8> {
    let mut out = header_text(cloud, "binary_little_endian", comment).into_bytes();
    for (i, p) in cloud.points.iter().enumerate() {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(classes) = &cloud.classes {
            out.push(classes[i]);
        }
    }
    out
}

/// Writes `cloud` as an ascii PLY.
pub fn write_ascii(cloud: &PlyCloud) -> Vec<u8> {
    let mut out = header_text(cloud, "ascii", None);
    for (i, p) in cloud.points.iter().enumerate() {
        out.push_str(&format!("{} {} {}", p[0], p[1], p[2]));
        if let Some(classes) = &cloud.classes {
            out.push_str(&format!(" {}", classes[i]));
        }
        out.push('\n');
    }
    out.into_bytes()
}

fn header_text(cloud: &PlyCloud, format: &str, comment: Option<&str>) -> String {
    let mut h = format!("ply\nformat {format} 1.0\n");
    if let Some(comment) = comment {
        h.push_str(&format!("comment {comment}\n"));
    }
    h.push_str(&format!(
        "element vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        cloud.points.len()
    ));
    if cloud.classes.is_some() {
        h.push_str("property uchar class\n");
    }
    h.push_str("end_header\n");
    h
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLittleEndian,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }

    /// Decodes one little-endian value; `bytes` has exactly `self.size()` bytes.
    fn decode_le(self, b: &[u8]) -> f64 {
        match self {
            Self::I8 => f64::from(b[0] as i8),
            Self::U8 => f64::from(b[0]),
            Self::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Self::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Self::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Self::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Self::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Self::F64 => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum PropertyKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone, PartialEq)]
struct Property {
    name: String,
    kind: PropertyKind,
}

#[derive(Debug, Clone, PartialEq)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(Debug, Clone, PartialEq)]
struct Header {
    format: Format,
    elements: Vec<Element>,
}

/// Where the vertex element keeps the properties we read.
struct VertexLayout {
    xyz: [usize; 3],
    class: Option<usize>,
}

/// Largest element count accepted, so a corrupt header cannot ask for absurd allocations.
const MAX_COUNT: usize = 1 << 31;

fn header_error(line: usize, reason: impl Into<String>) -> PlyError {
    PlyError::Header {
        line,
        reason: reason.into(),
    }
}

fn parse_header(bytes: &[u8]) -> Result<(Header, &[u8]), PlyError> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        line_no += 1;
        let line = next_header_line(bytes, &mut pos, line_no)?;
        let words: Vec<&str> = line.split_whitespace().collect();
        if line_no == 1 {
            if line != "ply" {
                return Err(header_error(
                    1,
                    format!("expected the magic `ply`, found `{line}`"),
                ));
            }
            continue;
        }
        match words.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => format = Some(parse_format(line_no, line, &words)?),
            Some("element") => elements.push(parse_element(line_no, line, &words)?),
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(header_error(line_no, "a property comes before any element"));
                };
                let property = parse_property(line_no, line, &words)?;
                if element.properties.iter().any(|p| p.name == property.name) {
                    return Err(header_error(
                        line_no,
                        format!(
                            "property `{}` is declared twice in element `{}`",
                            property.name, element.name
                        ),
                    ));
                }
                element.properties.push(property);
            }
            Some("end_header") => break,
            Some(other) => {
                return Err(header_error(
                    line_no,
                    format!("unknown header keyword `{other}`"),
                ));
            }
        }
    }
    let format = format.ok_or_else(|| header_error(line_no, "the header has no `format` line"))?;
    Ok((Header { format, elements }, &bytes[pos..]))
}

/// Header line `line_no`, starting at `*pos`, trimmed; moves `*pos` past it.
fn next_header_line<'a>(
    bytes: &'a [u8],
    pos: &mut usize,
    line_no: usize,
) -> Result<&'a str, PlyError> {
    let Some(end) = bytes[*pos..].iter().position(|&b| b == b'\n') else {
        return Err(header_error(line_no, "the header ends before `end_header`"));
    };
    let raw = &bytes[*pos..*pos + end];
    *pos += end + 1;
    Ok(std::str::from_utf8(raw)
        .map_err(|_| header_error(line_no, "the header line is not valid UTF-8"))?
        .trim_end_matches('\r')
        .trim())
}

/// `format <ascii|binary_little_endian> 1.0`.
fn parse_format(line_no: usize, line: &str, words: &[&str]) -> Result<Format, PlyError> {
    if words.len() != 3 {
        return Err(header_error(
            line_no,
            format!("malformed format line `{line}`"),
        ));
    }
    if words[2] != "1.0" {
        return Err(header_error(
            line_no,
            format!("unsupported PLY version `{}`", words[2]),
        ));
    }
    match words[1] {
        "ascii" => Ok(Format::Ascii),
        "binary_little_endian" => Ok(Format::BinaryLittleEndian),
        "binary_big_endian" => Err(header_error(
            line_no,
            "binary_big_endian PLY is not supported; convert it to \
             binary_little_endian or ascii",
        )),
        other => Err(header_error(line_no, format!("unknown format `{other}`"))),
    }
}

/// `element <name> <count>`, with no properties yet.
fn parse_element(line_no: usize, line: &str, words: &[&str]) -> Result<Element, PlyError> {
    if words.len() != 3 {
        return Err(header_error(
            line_no,
            format!("malformed element line `{line}`"),
        ));
    }
    let count: usize = words[2].parse().map_err(|_| {
        header_error(
            line_no,
            format!("element `{}` has a bad count `{}`", words[1], words[2]),
        )
    })?;
    if count > MAX_COUNT {
        return Err(header_error(
            line_no,
            format!("element `{}` count {count} is too large", words[1]),
        ));
    }
    Ok(Element {
        name: words[1].to_owned(),
        count,
        properties: Vec::new(),
    })
}

/// `property <type> <name>` or `property list <count type> <item type> <name>`.
fn parse_property(line_no: usize, line: &str, words: &[&str]) -> Result<Property, PlyError> {
    let scalar = |name: &str, what: &str, ty: &str| {
        Scalar::parse(ty).ok_or_else(|| {
            header_error(
                line_no,
                format!("property `{name}` has an unsupported {what}type `{ty}`"),
            )
        })
    };
    let (kind, name) = match words {
        ["property", "list", count, item, name] => {
            let count_t = scalar(name, "list count ", count)?;
            if !count_t.is_integer() {
                return Err(header_error(
                    line_no,
                    format!("property `{name}` has a non-integer list count type `{count}`"),
                ));
            }
            let item_t = scalar(name, "list item ", item)?;
            (
                PropertyKind::List {
                    count: count_t,
                    item: item_t,
                },
                *name,
            )
        }
        ["property", ty, name] => (PropertyKind::Scalar(scalar(name, "", ty)?), *name),
        _ => {
            return Err(header_error(
                line_no,
                format!("malformed property line `{line}`"),
            ));
        }
    };
    Ok(Property {
        name: name.to_owned(),
        kind,
    })
}

fn vertex_layout(header: &Header) -> Result<(usize, VertexLayout), PlyError> {
    let index = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| header_error(0, "the file has no `vertex` element"))?;
    let element = &header.elements[index];
    let find = |name: &str| element.properties.iter().position(|p| p.name == name);
    let mut xyz = [0; 3];
    for (slot, axis) in xyz.iter_mut().zip(["x", "y", "z"]) {
        let i = find(axis).ok_or_else(|| PlyError::MissingProperty {
            element: element.name.clone(),
            property: axis.to_owned(),
        })?;
        if !matches!(element.properties[i].kind, PropertyKind::Scalar(_)) {
            return Err(PlyError::UnsupportedProperty {
                element: element.name.clone(),
                property: axis.to_owned(),
                reason: "a coordinate must be a scalar, not a list".to_owned(),
            });
        }
        *slot = i;
    }
    let class = find("class").or_else(|| find("label"));
    if let Some(i) = class {
        match element.properties[i].kind {
            PropertyKind::Scalar(t) if t.is_integer() => {}
            _ => {
                return Err(PlyError::UnsupportedProperty {
                    element: element.name.clone(),
                    property: element.properties[i].name.clone(),
                    reason: "a class must be an integer scalar (uchar, int, ...)".to_owned(),
                });
            }
        }
    }
    Ok((index, VertexLayout { xyz, class }))
}

fn data_error(
    element: &Element,
    index: usize,
    property: &str,
    reason: impl Into<String>,
) -> PlyError {
    PlyError::Data {
        element: element.name.clone(),
        index,
        property: property.to_owned(),
        reason: reason.into(),
    }
}

/// Stores the values of one vertex into `out`, checking the class range.
fn push_vertex(
    element: &Element,
    index: usize,
    layout: &VertexLayout,
    values: &[f64],
    out: &mut PlyCloud,
) -> Result<(), PlyError> {
    let mut p = [0f32; 3];
    for (k, &i) in layout.xyz.iter().enumerate() {
        let v = values[i];
        if !v.is_finite() {
            return Err(data_error(
                element,
                index,
                &element.properties[i].name,
                format!("value {v} is not finite"),
            ));
        }
        p[k] = v as f32;
    }
    out.points.push(p);
    if let (Some(i), Some(classes)) = (layout.class, out.classes.as_mut()) {
        let v = values[i];
        if !(0.0..=255.0).contains(&v) {
            return Err(data_error(
                element,
                index,
                &element.properties[i].name,
                format!("class {v} is outside 0..=255"),
            ));
        }
        classes.push(v as u8);
    }
    Ok(())
}

fn empty_cloud(count: usize, layout: &VertexLayout) -> PlyCloud {
    PlyCloud {
        points: Vec::with_capacity(count.min(1 << 24)),
        classes: layout.class.map(|_| Vec::with_capacity(count.min(1 << 24))),
    }
}

fn read_ascii(header: &Header, body: &[u8]) -> Result<PlyCloud, PlyError> {
    let (vertex_index, layout) = vertex_layout(header)?;
    let text = std::str::from_utf8(body).map_err(|e| PlyError::Data {
        element: "body".to_owned(),
        index: 0,
        property: String::new(),
        reason: format!("ascii body is not valid UTF-8 at byte {}", e.valid_up_to()),
    })?;
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let vertex_element = &header.elements[vertex_index];
    let mut cloud = empty_cloud(vertex_element.count, &layout);
    let mut values = Vec::new();
    for (ei, element) in header.elements.iter().enumerate() {
        for index in 0..element.count {
            let line = lines.next().ok_or_else(|| {
                data_error(
                    element,
                    index,
                    "",
                    format!("the file ends after {index} of {} rows", element.count),
                )
            })?;
            read_ascii_row(element, index, line, &mut values)?;
            if ei == vertex_index {
                push_vertex(element, index, &layout, &values, &mut cloud)?;
            }
        }
        if ei == vertex_index {
            // Elements after the vertices do not matter; stop reading.
            return Ok(cloud);
        }
    }
    Ok(cloud)
}

/// Reads row `index` of `element` from `line` into `values`, one value per property (0 for a
/// list, which is checked and skipped).
fn read_ascii_row(
    element: &Element,
    index: usize,
    line: &str,
    values: &mut Vec<f64>,
) -> Result<(), PlyError> {
    let mut words = line.split_whitespace();
    values.clear();
    for property in &element.properties {
        let mut next = |t: Scalar| ascii_value(words.next(), t, element, index, &property.name);
        match property.kind {
            PropertyKind::Scalar(t) => values.push(next(t)?),
            PropertyKind::List { count, item } => {
                let n = next(count)?;
                if n < 0.0 {
                    return Err(data_error(
                        element,
                        index,
                        &property.name,
                        format!("negative list length {n}"),
                    ));
                }
                for _ in 0..n as usize {
                    next(item)?;
                }
                values.push(0.0);
            }
        }
    }
    if words.next().is_some() {
        return Err(data_error(
            element,
            index,
            "",
            "the row has more values than the element has properties",
        ));
    }
    Ok(())
}

/// One value of type `t` from `word`, the next word of the row (`None` at its end).
fn ascii_value(
    word: Option<&str>,
    t: Scalar,
    element: &Element,
    index: usize,
    property: &str,
) -> Result<f64, PlyError> {
    let word =
        word.ok_or_else(|| data_error(element, index, property, "the row has too few values"))?;
    let v: f64 = word.parse().map_err(|_| {
        data_error(
            element,
            index,
            property,
            format!("`{word}` is not a number"),
        )
    })?;
    if t.is_integer() && v.fract() != 0.0 {
        return Err(data_error(
            element,
            index,
            property,
            format!("`{word}` is not an integer"),
        ));
    }
    Ok(v)
}

fn read_binary(header: &Header, body: &[u8]) -> Result<PlyCloud, PlyError> {
    let (vertex_index, layout) = vertex_layout(header)?;
    let vertex_element = &header.elements[vertex_index];
    let mut cloud = empty_cloud(vertex_element.count, &layout);
    let mut pos = 0usize;
    let mut values = Vec::new();
    for (ei, element) in header.elements.iter().enumerate() {
        // Rows of no properties take no bytes: nothing to read, however many the header claims
        // (up to 2^31, which the fuzzer found took minutes to count through).
        if element.properties.is_empty() {
            continue;
        }
        for index in 0..element.count {
            read_binary_row(element, index, body, &mut pos, &mut values)?;
            if ei == vertex_index {
                push_vertex(element, index, &layout, &values, &mut cloud)?;
            }
        }
        if ei == vertex_index {
            return Ok(cloud);
        }
    }
    Ok(cloud)
}

/// Reads row `index` of `element` from `body` at `*pos` into `values`, one value per property
/// (0 for a list, which is skipped); moves `*pos` past the row.
fn read_binary_row(
    element: &Element,
    index: usize,
    body: &[u8],
    pos: &mut usize,
    values: &mut Vec<f64>,
) -> Result<(), PlyError> {
    values.clear();
    for property in &element.properties {
        let mut take = |t: Scalar| -> Result<f64, PlyError> {
            let size = t.size();
            let bytes = body.get(*pos..*pos + size).ok_or_else(|| {
                data_error(
                    element,
                    index,
                    &property.name,
                    format!(
                        "truncated data: the file ends at byte {} of the body",
                        body.len()
                    ),
                )
            })?;
            *pos += size;
            Ok(t.decode_le(bytes))
        };
        match property.kind {
            PropertyKind::Scalar(t) => values.push(take(t)?),
            PropertyKind::List { count, item } => {
                let n = take(count)?;
                if n < 0.0 {
                    return Err(data_error(
                        element,
                        index,
                        &property.name,
                        format!("negative list length {n}"),
                    ));
                }
                let skip = (n as usize).saturating_mul(item.size());
                if body.len().saturating_sub(*pos) < skip {
                    return Err(data_error(
                        element,
                        index,
                        &property.name,
                        "truncated data inside a list",
                    ));
                }
                *pos += skip;
                values.push(0.0);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn le(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    #[test]
    fn ascii_with_extra_properties_and_label() {
        let text = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nelement vertex 2\r\n\
                    property double x\r\nproperty double y\r\nproperty double z\r\n\
                    property float intensity\r\nproperty int label\r\nend_header\r\n\
                    1.5 2 3 0.7 4\r\n-1 -2 -3 0.1 13\r\n";
        let cloud = parse(text.as_bytes()).unwrap();
        assert_eq!(cloud.points, vec![[1.5, 2.0, 3.0], [-1.0, -2.0, -3.0]]);
        assert_eq!(cloud.classes, Some(vec![4, 13]));
    }

    #[test]
    fn ascii_without_classes_and_with_faces() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float z\nproperty float y\n\
                    property float x\nelement face 1\nproperty list uchar int vertex_indices\n\
                    end_header\n3 2 1\n6 5 4\n9 8 7\n3 0 1 2\n";
        let cloud = parse(text.as_bytes()).unwrap();
        assert_eq!(
            cloud.points,
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]
        );
        assert_eq!(cloud.classes, None);
    }

    #[test]
    fn binary_float_with_uchar_class() {
        let cloud = PlyCloud {
            points: vec![[0.0, 1.0, 2.0], [3.5, -4.25, 1e3]],
            classes: Some(vec![4, 7]),
        };
        assert_eq!(parse(&write_binary(&cloud)).unwrap(), cloud);
        assert_eq!(parse(&write_ascii(&cloud)).unwrap(), cloud);
    }

    #[test]
    fn binary_mixed_types_and_element_before_vertex() {
        // An element before the vertices, with a list, must be skipped byte-exactly.
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement camera 1\n\
                          property list uchar short stuff\nproperty ushort id\n\
                          element vertex 2\nproperty double x\nproperty short pad\nproperty float y\n\
                          property int z\nproperty char class\nend_header\n"
            .to_vec();
        bytes.push(2);
        bytes.extend_from_slice(&7i16.to_le_bytes());
        bytes.extend_from_slice(&8i16.to_le_bytes());
        bytes.extend_from_slice(&99u16.to_le_bytes());
        for (x, y, z, c) in [(1.25f64, 2.5f32, -3i32, 4i8), (10.0, 20.0, 30, 14)] {
            bytes.extend_from_slice(&x.to_le_bytes());
            bytes.extend_from_slice(&(-1i16).to_le_bytes());
            bytes.extend_from_slice(&y.to_le_bytes());
            bytes.extend_from_slice(&z.to_le_bytes());
            bytes.push(c as u8);
        }
        let cloud = parse(&bytes).unwrap();
        assert_eq!(cloud.points, vec![[1.25, 2.5, -3.0], [10.0, 20.0, 30.0]]);
        assert_eq!(cloud.classes, Some(vec![4, 14]));
    }

    #[test]
    fn empty_vertex_element_is_an_empty_cloud() {
        let text = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n";
        assert_eq!(parse(text.as_bytes()).unwrap().points.len(), 0);
    }

    fn err(bytes: &[u8]) -> String {
        parse(bytes).unwrap_err().to_string()
    }

    #[test]
    fn bad_magic_names_line_one() {
        let e = err(b"plx\nformat ascii 1.0\nend_header\n");
        assert!(e.contains("line 1") && e.contains("magic"), "{e}");
    }

    #[test]
    fn big_endian_is_rejected_clearly() {
        let e = err(b"ply\nformat binary_big_endian 1.0\nelement vertex 0\nend_header\n");
        assert!(
            e.contains("line 2") && e.contains("binary_big_endian"),
            "{e}"
        );
    }

    #[test]
    fn unsupported_type_names_property_and_line() {
        let e = err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty half y\nend_header\n");
        assert!(
            e.contains("line 5") && e.contains("`y`") && e.contains("half"),
            "{e}"
        );
    }

    #[test]
    fn missing_coordinate_is_named() {
        let e = err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n");
        assert!(e.contains("`z`") && e.contains("vertex"), "{e}");
    }

    #[test]
    fn missing_end_header_and_format() {
        let e = err(b"ply\nformat ascii 1.0\nelement vertex 1\n");
        assert!(e.contains("end_header"), "{e}");
        let e = err(b"ply\nelement vertex 0\nend_header\n");
        assert!(e.contains("format"), "{e}");
        let e = err(b"ply\nformat ascii 1.0\nproperty float x\nend_header\n");
        assert!(
            e.contains("line 3") && e.contains("before any element"),
            "{e}"
        );
        let e = err(b"ply\nformat ascii 1.0\nelement vertex many\nend_header\n");
        assert!(e.contains("line 3") && e.contains("many"), "{e}");
        let e = err(b"ply\nformat ascii 1.0\nelement face 0\nend_header\n");
        assert!(e.contains("no `vertex` element"), "{e}");
    }

    #[test]
    fn truncated_binary_names_vertex_and_property() {
        let mut bytes =
            b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n\
                          property float y\nproperty float z\nend_header\n"
                .to_vec();
        bytes.extend(le(&[1.0, 2.0, 3.0, 4.0]));
        let e = err(&bytes);
        assert!(
            e.contains("vertex 1") && e.contains("`y`") && e.contains("truncated"),
            "{e}"
        );
    }

    #[test]
    fn truncated_ascii_and_bad_numbers() {
        let head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                    property float z\nproperty uchar class\nend_header\n";
        let e = err(format!("{head}1 2 3 4\n").as_bytes());
        assert!(
            e.contains("vertex 1") && e.contains("ends after 1 of 2"),
            "{e}"
        );
        let e = err(format!("{head}1 2 3 4\n1 two 3 4\n").as_bytes());
        assert!(
            e.contains("vertex 1") && e.contains("`y`") && e.contains("two"),
            "{e}"
        );
        let e = err(format!("{head}1 2 3 4\n1 2 3\n").as_bytes());
        assert!(
            e.contains("vertex 1") && e.contains("`class`") && e.contains("too few"),
            "{e}"
        );
        let e = err(format!("{head}1 2 3 4 5\n1 2 3 4\n").as_bytes());
        assert!(e.contains("vertex 0") && e.contains("more values"), "{e}");
        let e = err(format!("{head}1 2 3 4.5\n1 2 3 4\n").as_bytes());
        assert!(e.contains("`class`") && e.contains("not an integer"), "{e}");
        let e = err(format!("{head}1 2 3 4\n1 2 nan 4\n").as_bytes());
        assert!(
            e.contains("vertex 1") && e.contains("`z`") && e.contains("not finite"),
            "{e}"
        );
    }

    #[test]
    fn class_out_of_range_and_float_class_are_rejected() {
        let e = err(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                      property float z\nproperty int class\nend_header\n0 0 0 300\n",
        );
        assert!(e.contains("`class`") && e.contains("300"), "{e}");
        let e = err(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                      property float z\nproperty float label\nend_header\n0 0 0 3\n",
        );
        assert!(e.contains("`label`") && e.contains("integer"), "{e}");
    }

    #[test]
    fn list_coordinate_is_rejected() {
        let e = err(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\n\
                      property float y\nproperty float z\nend_header\n1 0 0 0\n",
        );
        assert!(e.contains("`x`") && e.contains("list"), "{e}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig {
            cases: 64,
            rng_seed: proptest::test_runner::RngSeed::Fixed(7),
            ..Default::default()
        })]
        #[test]
        fn binary_and_ascii_round_trip(
            points in proptest::collection::vec(proptest::array::uniform3(-1e4f32..1e4), 0..50),
            with_classes in proptest::bool::ANY,
        ) {
            let classes = with_classes.then(|| points.iter().enumerate().map(|(i, _)| (i % 15) as u8).collect());
            let cloud = PlyCloud { points, classes };
            proptest::prop_assert_eq!(parse(&write_binary(&cloud)).unwrap(), cloud.clone());
            // ascii prints the shortest text that reads back as the same f32.
            proptest::prop_assert_eq!(parse(&write_ascii(&cloud)).unwrap(), cloud);
        }

        #[test]
        fn truncation_never_panics(cut in 0usize..200) {
            let cloud = PlyCloud { points: vec![[1.0, 2.0, 3.0]; 5], classes: Some(vec![4; 5]) };
            let bytes = write_binary(&cloud);
            let cut = cut.min(bytes.len());
            let result = parse(&bytes[..cut]);
            proptest::prop_assert_eq!(result.is_ok(), cut == bytes.len());
        }
    }
}
