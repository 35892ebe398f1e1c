//! A small PLY reader for `landing detect FILE.ply`: the `vertex` element's `x`, `y`, `z` and an
//! optional `class` (or `label`) property, from ascii or binary little-endian files. Other
//! properties and elements are skipped; list properties are allowed only outside `vertex`.

use std::path::Path;

use crate::ClientError;

/// The points of a PLY file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlyPoints {
    /// x, y, z of every vertex, in file order.
    pub points: Vec<[f32; 3]>,
    /// Per-point classes, when the file has a `class` or `label` property.
    pub classes: Option<Vec<u8>>,
}

/// Reads a PLY file.
pub fn read_ply(path: &Path) -> Result<PlyPoints, ClientError> {
    let bytes = std::fs::read(path).map_err(|e| ClientError::io(path, e))?;
    parse_ply(&bytes).map_err(|reason| ClientError::Recording {
        path: path.display().to_string(),
        reason,
    })
}

#[derive(Debug, Clone, Copy, PartialEq)]
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

    fn read_le(self, b: &[u8]) -> f64 {
        match self {
            Self::I8 => b[0] as i8 as f64,
            Self::U8 => b[0] as f64,
            Self::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Self::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Self::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Self::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Self::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Self::F64 => f64::from_le_bytes(b[..8].try_into().unwrap_or([0; 8])),
        }
    }
}

#[derive(Debug)]
enum Property {
    Scalar(String, Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// Parses a PLY file held in memory.
pub fn parse_ply(bytes: &[u8]) -> Result<PlyPoints, String> {
    const END: &[u8] = b"end_header";
    let end = bytes
        .windows(END.len())
        .position(|w| w == END)
        .ok_or("no `end_header` line")?;
    let mut body = end + END.len();
    if bytes.get(body) == Some(&b'\r') {
        body += 1;
    }
    if bytes.get(body) == Some(&b'\n') {
        body += 1;
    }
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| "header is not UTF-8")?;
    let mut lines = header.lines().map(str::trim).filter(|l| !l.is_empty());
    if lines.next() != Some("ply") {
        return Err("not a PLY file (first line is not `ply`)".into());
    }
    let mut ascii = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", "ascii", _] => ascii = Some(true),
            ["format", "binary_little_endian", _] => ascii = Some(false),
            ["format", other, ..] => {
                return Err(format!(
                    "format `{other}` is not supported (ascii or binary_little_endian)"
                ));
            }
            ["comment", ..] | ["obj_info", ..] => {}
            ["element", name, count] => elements.push(Element {
                name: (*name).to_owned(),
                count: count
                    .parse()
                    .map_err(|_| format!("bad element count `{count}`"))?,
                properties: Vec::new(),
            }),
            ["property", "list", c, i, _] => {
                let e = elements.last_mut().ok_or("property before any element")?;
                let count = Scalar::parse(c).ok_or(format!("unknown type `{c}`"))?;
                let item = Scalar::parse(i).ok_or(format!("unknown type `{i}`"))?;
                e.properties.push(Property::List { count, item });
            }
            ["property", ty, name] => {
                let e = elements.last_mut().ok_or("property before any element")?;
                let s = Scalar::parse(ty).ok_or(format!("unknown type `{ty}`"))?;
                e.properties.push(Property::Scalar((*name).to_owned(), s));
            }
            _ => return Err(format!("unexpected header line `{line}`")),
        }
    }
    let ascii = ascii.ok_or("no `format` line")?;
    let mut out = PlyPoints::default();
    let mut text = if ascii {
        Some(
            std::str::from_utf8(&bytes[body..])
                .map_err(|_| "ascii body is not UTF-8")?
                .split_whitespace(),
        )
    } else {
        None
    };
    let mut pos = body;
    for element in &elements {
        let is_vertex = element.name == "vertex";
        let index = |n: &str| {
            element
                .properties
                .iter()
                .position(|p| matches!(p, Property::Scalar(name, _) if name == n))
        };
        let (xi, yi, zi) = if is_vertex {
            let get = |n: &str| index(n).ok_or(format!("vertex element has no `{n}` property"));
            (get("x")?, get("y")?, get("z")?)
        } else {
            (0, 0, 0)
        };
        let ci = if is_vertex {
            index("class").or_else(|| index("label"))
        } else {
            None
        };
        if ci.is_some() {
            out.classes = Some(Vec::with_capacity(element.count));
        }
        if is_vertex {
            out.points.reserve(element.count);
        }
        let mut values = vec![0f64; element.properties.len()];
        for row in 0..element.count {
            for (k, p) in element.properties.iter().enumerate() {
                let mut next = |ty: Scalar| -> Result<f64, String> {
                    match text.as_mut() {
                        Some(words) => words
                            .next()
                            .ok_or(format!("{} row {row}: file ends early", element.name))?
                            .parse::<f64>()
                            .map_err(|e| format!("{} row {row}: {e}", element.name)),
                        None => {
                            let b = bytes
                                .get(pos..pos + ty.size())
                                .ok_or(format!("{} row {row}: file ends early", element.name))?;
                            pos += ty.size();
                            Ok(ty.read_le(b))
                        }
                    }
                };
                match p {
                    Property::Scalar(_, ty) => values[k] = next(*ty)?,
                    Property::List { count, item } => {
                        let n = next(*count)? as usize;
                        for _ in 0..n {
                            next(*item)?;
                        }
                    }
                }
            }
            if is_vertex {
                out.points
                    .push([values[xi] as f32, values[yi] as f32, values[zi] as f32]);
                if let (Some(c), Some(classes)) = (ci, out.classes.as_mut()) {
                    let v = values[c];
                    if !(0.0..=255.0).contains(&v) {
                        return Err(format!("vertex {row}: class {v} is outside 0..=255"));
                    }
                    classes.push(v as u8);
                }
            }
        }
    }
    if !elements.iter().any(|e| e.name == "vertex") {
        return Err("no `vertex` element".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_ascii_with_classes_and_faces() {
        let text = b"ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar label\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 1 4\n1 0.5 1 13\n3 0 1 1\n";
        let p = parse_ply(text).unwrap();
        assert_eq!(p.points, vec![[0.0, 0.0, 1.0], [1.0, 0.5, 1.0]]);
        assert_eq!(p.classes, Some(vec![4, 13]));
    }

    #[test]
    fn reads_binary_little_endian_doubles() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\nend_header\n".to_vec();
        for v in [1.5f64, -2.0, 3.25] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.push(200);
        let p = parse_ply(&b).unwrap();
        assert_eq!(p.points, vec![[1.5, -2.0, 3.25]]);
        assert_eq!(p.classes, None);
    }

    #[test]
    fn errors_name_the_problem() {
        assert!(
            parse_ply(b"ply\nformat binary_big_endian 1.0\nend_header\n")
                .unwrap_err()
                .contains("binary_big_endian")
        );
        assert!(
            parse_ply(
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n"
            )
            .unwrap_err()
            .contains("`y`")
        );
        assert!(parse_ply(b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n").unwrap_err().contains("ends early"));
        assert!(parse_ply(b"hello").is_err());
    }
}
