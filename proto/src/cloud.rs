//! The packed point-cloud layout of [`PointCloud`]: the one writer ([`pack`]) and reader
//! ([`unpack`]) that the SDK, the server and the recordings share.
//!
//! [`pack`] writes `x`, `y`, `z` as FLOAT32 at offsets 0, 4, 8, then `intensity` (FLOAT32) when
//! given, then `class` (UINT8, a `SemanticClass` number) when given, little-endian, with no
//! padding: stride 12, 13, 16 or 17. [`unpack`] reads any layout the API accepts (FLOAT32 or
//! FLOAT64 coordinates, fields at any offset within the stride, extra fields ignored).
//!
//! ```
//! use landing_proto::cloud;
//!
//! let points = [[0.0f32, 0.0, 10.0], [1.0, 0.0, 10.0]];
//! let packed = cloud::pack(&points, None, Some(&[4, 4]));
//! assert_eq!(packed.point_stride, 13);
//! let back = cloud::unpack(&packed)?;
//! assert_eq!(back.points, points);
//! assert_eq!(back.classes, Some(vec![4, 4]));
//! # Ok::<(), cloud::UnpackError>(())
//! ```

use crate::v1::{NumericType, PackedElementField, PointCloud};

/// Bytes of one point's `x`, `y`, `z` as written by [`pack`].
pub const XYZ_BYTES: u32 = 12;

/// Packs points (and, when given, one intensity and one class per point) into a cloud with no
/// pose, timestamp or frame id. A per-point slice shorter than `points` is padded with zeros;
/// callers that must refuse a short slice check lengths first.
pub fn pack(
    points: &[[f32; 3]],
    intensities: Option<&[f32]>,
    classes: Option<&[u8]>,
) -> PointCloud {
    let mut fields = vec![
        field("x", 0, NumericType::Float32),
        field("y", 4, NumericType::Float32),
        field("z", 8, NumericType::Float32),
    ];
    let mut stride = XYZ_BYTES;
    if intensities.is_some() {
        fields.push(field("intensity", stride, NumericType::Float32));
        stride += 4;
    }
    if classes.is_some() {
        fields.push(field("class", stride, NumericType::Uint8));
        stride += 1;
    }
    let mut data = Vec::with_capacity(points.len() * stride as usize);
    for (i, p) in points.iter().enumerate() {
        for c in p {
            data.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(v) = intensities {
            data.extend_from_slice(&v.get(i).copied().unwrap_or(0.0).to_le_bytes());
        }
        if let Some(v) = classes {
            data.push(v.get(i).copied().unwrap_or(0));
        }
    }
    PointCloud {
        timestamp: None,
        frame_id: String::new(),
        pose: None,
        point_stride: stride,
        fields,
        data: data.into(),
    }
}

/// The size in bytes of a packed field's type; `None` for `NUMERIC_TYPE_UNSPECIFIED`.
pub fn numeric_size(t: NumericType) -> Option<usize> {
    match t {
        NumericType::Unspecified => None,
        NumericType::Uint8 | NumericType::Int8 => Some(1),
        NumericType::Uint16 | NumericType::Int16 => Some(2),
        NumericType::Uint32 | NumericType::Int32 | NumericType::Float32 => Some(4),
        NumericType::Float64 => Some(8),
    }
}

/// A point cloud read back from its packed form.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Unpacked {
    /// Points in the cloud's own frame (its `pose` moves them to the world).
    pub points: Vec<[f32; 3]>,
    /// Per-point classes, when the cloud has a `class` field.
    pub classes: Option<Vec<u8>>,
    /// Per-point intensities, when the cloud has an `intensity` field.
    pub intensities: Option<Vec<f32>>,
}

/// Why [`unpack`] could not read a cloud: the field of [`PointCloud`] at fault and the reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnpackError {
    /// `point_cloud.point_stride`, `point_cloud.data` or `point_cloud.fields`.
    pub field: &'static str,
    /// What is wrong with it, with the bad value.
    pub reason: String,
}

impl std::fmt::Display for UnpackError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.field, self.reason)
    }
}

impl std::error::Error for UnpackError {}

/// Reads a packed cloud: `x`, `y`, `z` (any numeric type, usually FLOAT32 or FLOAT64) and the
/// optional `intensity` and `class` fields. Does not judge the values (the server checks that
/// coordinates are finite and in range, naming the point).
pub fn unpack(cloud: &PointCloud) -> Result<Unpacked, UnpackError> {
    let stride = cloud.point_stride as usize;
    if stride == 0 {
        return Err(UnpackError {
            field: "point_cloud.point_stride",
            reason: "must be > 0".into(),
        });
    }
    if !cloud.data.len().is_multiple_of(stride) {
        return Err(UnpackError {
            field: "point_cloud.data",
            reason: format!(
                "{} bytes is not a multiple of the stride {stride}",
                cloud.data.len()
            ),
        });
    }
    let find = |name: &str| cloud.fields.iter().find(|f| f.name == name);
    let mut xyz = Vec::with_capacity(3);
    for name in ["x", "y", "z"] {
        xyz.push(find(name).ok_or_else(|| UnpackError {
            field: "point_cloud.fields",
            reason: format!("no `{name}` field"),
        })?);
    }
    let intensity = find("intensity");
    let class = find("class");
    let n = cloud.data.len() / stride;
    let mut out = Unpacked {
        points: Vec::with_capacity(n),
        classes: class.map(|_| Vec::with_capacity(n)),
        intensities: intensity.map(|_| Vec::with_capacity(n)),
    };
    let bad = |name: &str| UnpackError {
        field: "point_cloud.fields",
        reason: format!("field `{name}` does not fit in the stride or has an unknown type"),
    };
    for point in cloud.data.chunks_exact(stride) {
        let mut p = [0f32; 3];
        for (k, f) in xyz.iter().enumerate() {
            p[k] = read(f, point).ok_or_else(|| bad(&f.name))? as f32;
        }
        out.points.push(p);
        if let (Some(f), Some(v)) = (intensity, out.intensities.as_mut()) {
            v.push(read(f, point).ok_or_else(|| bad("intensity"))? as f32);
        }
        if let (Some(f), Some(v)) = (class, out.classes.as_mut()) {
            v.push(read(f, point).ok_or_else(|| bad("class"))? as u8);
        }
    }
    Ok(out)
}

fn field(name: &str, offset: u32, ty: NumericType) -> PackedElementField {
    PackedElementField {
        name: name.to_owned(),
        offset,
        r#type: ty as i32,
    }
}

/// One field of one point as `f64`; `None` when it overruns the point or has no known type.
fn read(f: &PackedElementField, point: &[u8]) -> Option<f64> {
    let ty = NumericType::try_from(f.r#type).ok()?;
    let o = f.offset as usize;
    let bytes = point.get(o..o + numeric_size(ty)?)?;
    Some(match ty {
        NumericType::Float32 => f32::from_le_bytes(bytes.try_into().ok()?) as f64,
        NumericType::Float64 => f64::from_le_bytes(bytes.try_into().ok()?),
        NumericType::Uint8 => bytes[0] as f64,
        NumericType::Int8 => bytes[0] as i8 as f64,
        NumericType::Uint16 => u16::from_le_bytes(bytes.try_into().ok()?) as f64,
        NumericType::Int16 => i16::from_le_bytes(bytes.try_into().ok()?) as f64,
        NumericType::Uint32 => u32::from_le_bytes(bytes.try_into().ok()?) as f64,
        NumericType::Int32 => i32::from_le_bytes(bytes.try_into().ok()?) as f64,
        NumericType::Unspecified => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_writes_every_layout_and_unpack_reads_it_back() {
        let points = [[1.5f32, -2.0, 3.25], [0.0, 1e6, -7.0]];
        let intensities = [0.5f32, 9.0];
        let classes = [4u8, 13];
        for (i, c, stride) in [
            (None, None, 12),
            (Some(&intensities[..]), None, 16),
            (None, Some(&classes[..]), 13),
            (Some(&intensities[..]), Some(&classes[..]), 17),
        ] {
            let packed = pack(&points, i, c);
            assert_eq!(packed.point_stride, stride);
            assert_eq!(packed.data.len(), 2 * stride as usize);
            let back = unpack(&packed).unwrap();
            assert_eq!(back.points, points);
            assert_eq!(back.intensities.as_deref(), i);
            assert_eq!(back.classes.as_deref(), c);
        }
    }

    #[test]
    fn float64_coordinates_and_extra_fields_are_read() {
        let mut data = Vec::new();
        for v in [1.0f64, 2.0, 3.0] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        data.extend_from_slice(&7u32.to_le_bytes());
        let cloud = PointCloud {
            point_stride: 28,
            fields: vec![
                field("x", 0, NumericType::Float64),
                field("y", 8, NumericType::Float64),
                field("z", 16, NumericType::Float64),
                field("ring", 24, NumericType::Uint32),
            ],
            data: data.into(),
            ..Default::default()
        };
        assert_eq!(unpack(&cloud).unwrap().points, [[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn bad_layouts_name_their_field() {
        let good = pack(&[[0.0; 3]], None, None);
        let mut c = good.clone();
        c.point_stride = 0;
        assert_eq!(unpack(&c).unwrap_err().field, "point_cloud.point_stride");
        let mut c = good.clone();
        c.data = c.data.slice(..5);
        assert_eq!(unpack(&c).unwrap_err().field, "point_cloud.data");
        let mut c = good.clone();
        c.fields.pop();
        let e = unpack(&c).unwrap_err();
        assert_eq!(e.to_string(), "point_cloud.fields: no `z` field");
        let mut c = good;
        c.fields[0].offset = 10;
        assert_eq!(unpack(&c).unwrap_err().field, "point_cloud.fields");
    }
}
