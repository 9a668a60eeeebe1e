//! VTK XML PolyData (`.vtp`) reader.
//!
//! Written here because vtkio cannot read the files users have (see `docs/DEPENDENCIES.md`):
//! VMTK writes zlib-compressed arrays with empty sections, ParaView writes raw appended data.
//! The XML part is parsed with quick-xml up to `<AppendedData>`; the appended bytes after the
//! `_` marker are binary (not UTF-8) and are sliced by hand. Every `DataArray`, whatever its
//! `format`, goes through [`decode_array`].

use super::polydata::{CellArray, NamedArray, PolyData, Values};
use flate2::read::ZlibDecoder;
use nalgebra::Point3;
use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use std::borrow::Cow;
use std::collections::HashMap;
use std::io::Read;

/// Parses a whole `.vtp` file.
#[cfg(test)]
pub(crate) fn parse(bytes: &[u8]) -> Result<PolyData, String> {
    parse_within(bytes, u64::MAX)
}

/// Parses a whole `.vtp` file whose binary arrays hold at most `max_inflated` bytes in all once
/// decoded: the block headers are added up before any block is inflated, so a file announcing
/// more (a corrupt header, a decompression bomb) is refused before it takes the memory.
pub(crate) fn parse_within(bytes: &[u8], max_inflated: u64) -> Result<PolyData, String> {
    let header = scan(bytes)?;
    let piece = header.piece.ok_or("has no <Piece> element: it holds no polydata")?;
    let announced = header.arrays.iter().fold(0u64, |sum, spec| sum.saturating_add(announced_size(spec, &header)));
    if announced > max_inflated {
        return Err(format!(
            "its binary arrays announce {} once decoded, more than the {} a run reads from one file (a tenth of \
             --max-memory): a corrupt file or a decompression bomb; if the file is genuine, raise --max-memory",
            crate::data::diagnostics::show_bytes(announced as f64),
            crate::data::diagnostics::show_bytes(max_inflated as f64)
        ));
    }
    let decoded = header
        .arrays
        .iter()
        .map(|spec| {
            let values = decode_array(spec, &header).map_err(|e| format!("DataArray '{}': {e}", spec.name))?;
            Ok((spec, values))
        })
        .collect::<Result<Vec<_>, String>>()?;
    assemble(&piece, decoded)
}

/// Where a `DataArray` sits in the `Piece`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Section {
    PointData,
    CellData,
    Points,
    Verts,
    Lines,
    Polys,
    Strips,
}

impl Section {
    fn from_tag(tag: &str) -> Option<Section> {
        Some(match tag {
            "PointData" => Section::PointData,
            "CellData" => Section::CellData,
            "Points" => Section::Points,
            "Verts" => Section::Verts,
            "Lines" => Section::Lines,
            "Polys" => Section::Polys,
            "Strips" => Section::Strips,
            _ => return None,
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Ascii,
    Binary,
    Appended,
}

/// Element types of `DataArray`s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    I16,
    I32,
    I64,
    U8,
    U16,
    U32,
    U64,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Result<Scalar, String> {
        Ok(match name {
            "Int8" | "Char" => Scalar::I8,
            "Int16" => Scalar::I16,
            "Int32" => Scalar::I32,
            "Int64" => Scalar::I64,
            "UInt8" => Scalar::U8,
            "UInt16" => Scalar::U16,
            "UInt32" => Scalar::U32,
            "UInt64" => Scalar::U64,
            "Float32" => Scalar::F32,
            "Float64" => Scalar::F64,
            other => {
                return Err(format!(
                    "unsupported data type '{other}' (use Int8..Int64, UInt8..UInt64, Float32 or Float64)"
                ))
            }
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Debug)]
struct ArraySpec {
    section: Section,
    name: String,
    scalar: Scalar,
    components: usize,
    format: Format,
    offset: Option<usize>,
    /// Inline content (ascii numbers or base64), whitespace included.
    text: String,
}

#[derive(Debug, Clone, Copy, Default)]
struct Piece {
    points: usize,
    verts: usize,
    lines: usize,
    strips: usize,
    polys: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Raw,
    Base64,
}

/// The `<AppendedData>` block: bytes after the `_` marker, to which `offset`s are relative.
#[derive(Debug)]
struct Appended<'a> {
    encoding: Encoding,
    data: &'a [u8],
    /// Sorted distinct offsets of all appended arrays: a base64 array ends where the next begins.
    offsets: Vec<usize>,
}

/// File-wide binary settings from `<VTKFile>`.
#[derive(Debug, Clone, Copy)]
struct Binary {
    big_endian: bool,
    /// Size in bytes of the UInt32/UInt64 block headers.
    header_size: usize,
    compressed: bool,
}

#[derive(Debug)]
struct Header<'a> {
    binary: Binary,
    piece: Option<Piece>,
    arrays: Vec<ArraySpec>,
    appended: Option<Appended<'a>>,
}

/// Reads the XML structure (everything up to the appended data) and collects the array specs.
fn scan(bytes: &[u8]) -> Result<Header<'_>, String> {
    let mut reader = Reader::from_reader(bytes);
    let mut stack: Vec<String> = Vec::new();
    let mut binary = None;
    let mut piece = None;
    let mut arrays: Vec<ArraySpec> = Vec::new();
    let mut open_array: Option<ArraySpec> = None;
    loop {
        let event = reader.read_event().map_err(|e| {
            format!("is not valid VTK XML (XML error near byte {}: {e}); re-export it", reader.error_position())
        })?;
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let tag = local_name_of(e);
                let is_empty = matches!(event, Event::Empty(_));
                let attrs = attributes(e)?;
                match tag.as_str() {
                    "VTKFile" => binary = Some(file_settings(&attrs)?),
                    "Piece" => {
                        if piece.is_some() {
                            return Err("has more than one <Piece>; only single-piece polydata is supported \
                                        (merge the pieces, e.g. with ParaView's Merge Blocks, and save again)"
                                .into());
                        }
                        piece = Some(piece_counts(&attrs)?);
                    }
                    "DataArray" => {
                        let section = stack.last().and_then(|p| Section::from_tag(p));
                        let spec = section.map(|s| array_spec(s, &attrs)).transpose()?;
                        if is_empty {
                            arrays.extend(spec);
                        } else {
                            open_array = spec;
                        }
                    }
                    "AppendedData" => {
                        let start = reader.buffer_position() as usize;
                        let appended = appended_block(bytes, start, &attrs, &arrays)?;
                        let binary = binary.ok_or("has no <VTKFile> root element")?;
                        return Ok(Header { binary, piece, arrays, appended: Some(appended) });
                    }
                    _ => {}
                }
                if !is_empty {
                    stack.push(tag);
                }
            }
            Event::End(_) if stack.pop().as_deref() == Some("DataArray") => arrays.extend(open_array.take()),
            Event::Text(t) => {
                if let (Some(spec), Some("DataArray")) = (open_array.as_mut(), stack.last().map(String::as_str)) {
                    spec.text.push_str(&t);
                }
            }
            Event::Eof => match stack.last() {
                Some(open) => return Err(format!("ends inside <{open}>: the file is truncated; re-export it")),
                None => break,
            },
            _ => {}
        }
    }
    let binary = binary.ok_or("has no <VTKFile> root element: it is not a VTK XML file")?;
    Ok(Header { binary, piece, arrays, appended: None })
}

fn local_name_of(e: &BytesStart) -> String {
    let name = e.local_name();
    let name: &str = name.as_ref();
    name.to_string()
}

fn attributes(e: &BytesStart) -> Result<HashMap<String, String>, String> {
    e.attributes()
        .map(|a| {
            let a = a.map_err(|err| format!("has a malformed XML attribute: {err}"))?;
            let key = a.key.local_name();
            let key: &str = key.as_ref();
            Ok((key.to_string(), a.value.trim().to_string()))
        })
        .collect()
}

fn file_settings(attrs: &HashMap<String, String>) -> Result<Binary, String> {
    match attrs.get("type").map(String::as_str) {
        Some("PolyData") => {}
        Some(other) => {
            return Err(format!(
                "is a VTK XML '{other}' file, not PolyData; save the surface or centerlines as .vtp polydata"
            ))
        }
        None => return Err("has no 'type' attribute on <VTKFile>".into()),
    }
    let big_endian = match attrs.get("byte_order").map(String::as_str) {
        None | Some("LittleEndian") => false,
        Some("BigEndian") => true,
        Some(other) => return Err(format!("has an unknown byte_order '{other}'")),
    };
    let header_size = match attrs.get("header_type").map(String::as_str) {
        None | Some("UInt32") => 4,
        Some("UInt64") => 8,
        Some(other) => return Err(format!("has an unsupported header_type '{other}' (UInt32 or UInt64)")),
    };
    let compressed = match attrs.get("compressor").map(String::as_str) {
        None | Some("") => false,
        Some("vtkZLibDataCompressor") => true,
        Some(other) => {
            return Err(format!(
                "uses the compressor '{other}'; only vtkZLibDataCompressor is supported \
                 (save with zlib compression or none)"
            ))
        }
    };
    Ok(Binary { big_endian, header_size, compressed })
}

fn count_attr(attrs: &HashMap<String, String>, key: &str) -> Result<usize, String> {
    match attrs.get(key) {
        None => Ok(0),
        Some(v) => v.parse().map_err(|_| format!("has {key}=\"{v}\", which is not a count")),
    }
}

fn piece_counts(attrs: &HashMap<String, String>) -> Result<Piece, String> {
    Ok(Piece {
        points: count_attr(attrs, "NumberOfPoints")?,
        verts: count_attr(attrs, "NumberOfVerts")?,
        lines: count_attr(attrs, "NumberOfLines")?,
        strips: count_attr(attrs, "NumberOfStrips")?,
        polys: count_attr(attrs, "NumberOfPolys")?,
    })
}

fn array_spec(section: Section, attrs: &HashMap<String, String>) -> Result<ArraySpec, String> {
    let name = attrs.get("Name").cloned().unwrap_or_default();
    let ctx = |e: String| format!("DataArray '{name}': {e}");
    let scalar = Scalar::parse(attrs.get("type").map_or("", String::as_str)).map_err(ctx)?;
    let components = match attrs.get("NumberOfComponents") {
        None => 1,
        Some(v) => v.parse().ok().filter(|&c| c > 0).ok_or_else(|| ctx(format!("bad NumberOfComponents '{v}'")))?,
    };
    let format = match attrs.get("format").map(String::as_str) {
        Some("ascii") => Format::Ascii,
        Some("binary") => Format::Binary,
        Some("appended") => Format::Appended,
        other => return Err(ctx(format!("unknown format {other:?} (ascii, binary or appended)"))),
    };
    let offset = match attrs.get("offset") {
        None => None,
        Some(v) => Some(v.parse().map_err(|_| ctx(format!("bad offset '{v}'")))?),
    };
    if format == Format::Appended && offset.is_none() {
        return Err(ctx("is appended but has no offset".into()));
    }
    Ok(ArraySpec { section, name, scalar, components, format, offset, text: String::new() })
}

/// Locates the appended bytes: they start after the first `_` following the start tag.
fn appended_block<'a>(
    bytes: &'a [u8],
    start: usize,
    attrs: &HashMap<String, String>,
    arrays: &[ArraySpec],
) -> Result<Appended<'a>, String> {
    let encoding = match attrs.get("encoding").map(String::as_str) {
        Some("raw") => Encoding::Raw,
        Some("base64") | None => Encoding::Base64,
        Some(other) => return Err(format!("has <AppendedData encoding=\"{other}\"> (raw or base64 expected)")),
    };
    let rest = bytes.get(start..).unwrap_or_default();
    let underscore = rest.iter().position(|&b| b == b'_').ok_or("has <AppendedData> without the '_' marker")?;
    let mut data = &rest[underscore + 1..];
    if encoding == Encoding::Base64 {
        let end = data.iter().position(|&b| b == b'<').unwrap_or(data.len());
        data = &data[..end];
    }
    let mut offsets: Vec<usize> = arrays.iter().filter_map(|a| a.offset).collect();
    offsets.sort_unstable();
    offsets.dedup();
    Ok(Appended { encoding, data, offsets })
}

/// Decodes one `DataArray`, whatever its format, into numbers.
fn decode_array(spec: &ArraySpec, header: &Header) -> Result<Values, String> {
    let binary = header.binary;
    let payload: Cow<[u8]> = match spec.format {
        Format::Ascii => return parse_ascii(&spec.text, spec.scalar),
        Format::Binary => Cow::Owned(unpack(&decode_base64(spec.text.as_bytes())?, binary)?),
        Format::Appended => {
            let appended = header.appended.as_ref().ok_or("is appended but the file has no <AppendedData>")?;
            let offset = spec.offset.unwrap_or(0);
            let block = appended_slice(appended, offset)?;
            match appended.encoding {
                Encoding::Raw => Cow::Owned(unpack(block, binary)?),
                Encoding::Base64 => Cow::Owned(unpack(&decode_base64(block)?, binary)?),
            }
        }
    };
    to_values(&payload, spec.scalar, binary.big_endian)
}

/// The appended bytes of the array at `offset`: to the end for raw data (the block header
/// says how much is used), to the next array's offset for base64 text.
fn appended_slice<'a>(appended: &Appended<'a>, offset: usize) -> Result<&'a [u8], String> {
    let len = appended.data.len();
    if offset > len {
        return Err(format!("offset {offset} is beyond the {len} bytes of appended data: the file is truncated"));
    }
    let end = match appended.encoding {
        Encoding::Raw => len,
        Encoding::Base64 => appended.offsets.iter().copied().find(|&o| o > offset).unwrap_or(len).min(len),
    };
    Ok(&appended.data[offset..end])
}

/// Decodes base64 made of one or more separately padded chunks (VTK encodes the compression
/// header and the data as separate base64 streams, so `=` padding may appear mid-text).
fn decode_base64(text: &[u8]) -> Result<Vec<u8>, String> {
    use base64::Engine;
    let clean: Vec<u8> = text.iter().copied().filter(|b| !b.is_ascii_whitespace()).collect();
    let mut out = Vec::with_capacity(clean.len() / 4 * 3);
    let mut start = 0;
    while start < clean.len() {
        let pad = clean[start..].iter().position(|&b| b == b'=').map(|p| start + p);
        let end = match pad {
            Some(p) => p + clean[p..].iter().take_while(|&&b| b == b'=').count(),
            None => clean.len(),
        };
        let chunk = base64::engine::general_purpose::STANDARD
            .decode(&clean[start..end])
            .map_err(|e| format!("invalid base64 data ({e})"))?;
        out.extend_from_slice(&chunk);
        start = end;
    }
    Ok(out)
}

/// The decoded size a binary array's header announces (0 for ascii arrays, and where the header
/// cannot be read: decoding then says what is wrong), read without inflating anything.
fn announced_size(spec: &ArraySpec, header: &Header) -> u64 {
    let binary = header.binary;
    let words = 3 * binary.header_size;
    // Base64 text is decoded in groups of four characters giving three bytes.
    let prefix = |text: &[u8]| -> Vec<u8> {
        let chars: Vec<u8> =
            text.iter().copied().filter(|b| !b.is_ascii_whitespace()).take(4 * words.div_ceil(3)).collect();
        let whole = chars.len() / 4 * 4;
        decode_base64(&chars[..whole]).unwrap_or_default()
    };
    let head: Vec<u8> = match spec.format {
        Format::Ascii => return 0,
        Format::Binary => prefix(spec.text.as_bytes()),
        Format::Appended => {
            let (Some(appended), Some(offset)) = (header.appended.as_ref(), spec.offset) else { return 0 };
            let Ok(block) = appended_slice(appended, offset) else { return 0 };
            match appended.encoding {
                Encoding::Raw => block[..block.len().min(words)].to_vec(),
                Encoding::Base64 => prefix(block),
            }
        }
    };
    let word = |k: usize| header_word(&head, k * binary.header_size, binary).ok().map(|w| w as u64);
    if !binary.compressed {
        return word(0).unwrap_or(0);
    }
    match (word(0), word(1), word(2)) {
        (Some(0), _, _) => 0,
        (Some(blocks), Some(size), Some(last)) => {
            let last = if last == 0 { size } else { last };
            (blocks - 1).saturating_mul(size).saturating_add(last)
        }
        _ => 0,
    }
}

/// Reads an unsigned header word of `size` bytes at `at`.
fn header_word(bytes: &[u8], at: usize, binary: Binary) -> Result<usize, String> {
    let size = binary.header_size;
    let word = bytes.get(at..at + size).ok_or("binary block header is truncated")?;
    let mut le = [0u8; 8];
    le[..size].copy_from_slice(word);
    if binary.big_endian {
        le[..size].reverse();
    }
    usize::try_from(u64::from_le_bytes(le)).map_err(|_| "binary block header is out of range".to_string())
}

/// Strips the block header from binary data and inflates it when the file is compressed.
/// Uncompressed: `[nbytes] data`. Compressed: `[nblocks, blocksize, lastblocksize, csize...]`
/// followed by the zlib blocks.
fn unpack(bytes: &[u8], binary: Binary) -> Result<Vec<u8>, String> {
    let h = binary.header_size;
    if !binary.compressed {
        let n = header_word(bytes, 0, binary)?;
        return bytes.get(h..h.saturating_add(n)).map(<[u8]>::to_vec).ok_or_else(|| {
            format!(
                "block announces {n} bytes but only {} follow: the file is truncated",
                bytes.len().saturating_sub(h)
            )
        });
    }
    let nblocks = header_word(bytes, 0, binary)?;
    let block_size = header_word(bytes, h, binary)?;
    let last_size = header_word(bytes, 2 * h, binary)?;
    let header_len = nblocks.checked_add(3).and_then(|n| n.checked_mul(h)).filter(|&l| l <= bytes.len());
    let mut at = header_len.ok_or("compression header announces more blocks than the data holds")?;
    let mut out = Vec::new();
    for block in 0..nblocks {
        let csize = header_word(bytes, (3 + block) * h, binary)?;
        let expected = if block + 1 == nblocks && last_size != 0 { last_size } else { block_size };
        let data = at
            .checked_add(csize)
            .and_then(|end| bytes.get(at..end))
            .ok_or_else(|| format!("compressed block {block} runs past the end of the data: the file is truncated"))?;
        inflate(data, expected, &mut out).map_err(|e| format!("compressed block {block}: {e}"))?;
        at += csize;
    }
    Ok(out)
}

/// Inflates one zlib block, which must give exactly `expected` bytes (reading at most one more,
/// so a corrupt header cannot make us allocate without bound).
fn inflate(data: &[u8], expected: usize, out: &mut Vec<u8>) -> Result<(), String> {
    let before = out.len();
    ZlibDecoder::new(data)
        .take(expected as u64 + 1)
        .read_to_end(out)
        .map_err(|e| format!("zlib data is corrupt ({e})"))?;
    let got = out.len() - before;
    if got != expected {
        return Err(format!("inflates to {got} bytes instead of {expected}"));
    }
    Ok(())
}

/// Turns raw little- or big-endian bytes into numbers of the array's type.
fn to_values(bytes: &[u8], scalar: Scalar, big_endian: bool) -> Result<Values, String> {
    let size = scalar.size();
    if !bytes.len().is_multiple_of(size) {
        return Err(format!("holds {} bytes, not a whole number of {size}-byte values", bytes.len()));
    }
    let words = bytes.chunks_exact(size).map(|c| {
        let mut w = [0u8; 8];
        w[..size].copy_from_slice(c);
        if big_endian {
            w[..size].reverse();
        }
        w
    });
    let head = |w: [u8; 8]| -> [u8; 4] { [w[0], w[1], w[2], w[3]] };
    Ok(match scalar {
        Scalar::F32 => Values::Float(words.map(|w| f32::from_le_bytes(head(w)) as f64).collect()),
        Scalar::F64 => Values::Float(words.map(f64::from_le_bytes).collect()),
        Scalar::I8 => Values::Int(words.map(|w| w[0] as i8 as i64).collect()),
        Scalar::U8 => Values::Int(words.map(|w| w[0] as i64).collect()),
        Scalar::I16 => Values::Int(words.map(|w| i16::from_le_bytes([w[0], w[1]]) as i64).collect()),
        Scalar::U16 => Values::Int(words.map(|w| u16::from_le_bytes([w[0], w[1]]) as i64).collect()),
        Scalar::I32 => Values::Int(words.map(|w| i32::from_le_bytes(head(w)) as i64).collect()),
        Scalar::U32 => Values::Int(words.map(|w| u32::from_le_bytes(head(w)) as i64).collect()),
        Scalar::I64 => Values::Int(words.map(i64::from_le_bytes).collect()),
        Scalar::U64 => Values::Int(
            words
                .map(|w| {
                    i64::try_from(u64::from_le_bytes(w)).map_err(|_| "holds a UInt64 value beyond Int64".to_string())
                })
                .collect::<Result<_, _>>()?,
        ),
    })
}

fn parse_ascii(text: &str, scalar: Scalar) -> Result<Values, String> {
    let bad = |i: usize, t: &str| format!("ascii value {i} '{t}' is not a number");
    let tokens = text.split_ascii_whitespace().enumerate();
    Ok(if scalar.is_float() {
        Values::Float(tokens.map(|(i, t)| t.parse::<f64>().map_err(|_| bad(i, t))).collect::<Result<_, _>>()?)
    } else {
        Values::Int(tokens.map(|(i, t)| t.parse::<i64>().map_err(|_| bad(i, t))).collect::<Result<_, _>>()?)
    })
}

/// Builds the polydata from the decoded arrays and checks counts against the `Piece`.
fn assemble(piece: &Piece, arrays: Vec<(&ArraySpec, Values)>) -> Result<PolyData, String> {
    let mut pd = PolyData::default();
    let mut cell_parts: HashMap<(Section, &str), Vec<i64>> = HashMap::new();
    let mut points = None;
    for (spec, values) in arrays {
        let named = || NamedArray { name: spec.name.clone(), components: spec.components, values: values.clone() };
        match spec.section {
            Section::PointData => pd.point_data.push(named()),
            Section::CellData => pd.cell_data.push(named()),
            Section::Points => points = Some((spec.components, values)),
            s => {
                let ints =
                    values.as_int().ok_or_else(|| format!("cell array '{}' is not of an integer type", spec.name))?;
                cell_parts.insert((s, spec.name.as_str()), ints.to_vec());
            }
        }
    }
    pd.points = match points {
        Some((3, v)) => v.to_f64().chunks_exact(3).map(|c| Point3::new(c[0], c[1], c[2])).collect(),
        Some((c, _)) => return Err(format!("<Points> has {c} components; 3 are needed")),
        None if piece.points == 0 => Vec::new(),
        None => return Err("has no <Points> array: it holds no coordinates; re-export it".into()),
    };
    if pd.points.len() != piece.points {
        return Err(format!("<Points> holds {} points but NumberOfPoints is {}", pd.points.len(), piece.points));
    }
    let mut cells = |section: Section, n: usize| -> Result<CellArray, String> {
        let name = format!("{section:?}");
        match (cell_parts.remove(&(section, "connectivity")), cell_parts.remove(&(section, "offsets"))) {
            (Some(conn), Some(offs)) => CellArray::from_offsets(&offs, &conn, n).map_err(|e| format!("<{name}> {e}")),
            _ if n == 0 => Ok(CellArray::new()),
            _ => Err(format!("<{name}> announces {n} cells but lacks its connectivity/offsets arrays")),
        }
    };
    pd.verts = cells(Section::Verts, piece.verts)?;
    pd.lines = cells(Section::Lines, piece.lines)?;
    pd.polys = cells(Section::Polys, piece.polys)?;
    pd.strips = cells(Section::Strips, piece.strips)?;
    pd.validate()?;
    Ok(pd)
}

#[cfg(test)]
mod tests {
    use super::*;
    use base64::Engine;
    use std::io::Write;

    fn b64(bytes: &[u8]) -> String {
        base64::engine::general_purpose::STANDARD.encode(bytes)
    }

    fn f32_bytes(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }
    fn i64_bytes(v: &[i64]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    /// Uncompressed block: byte count header then the data.
    fn plain_block(data: &[u8], header8: bool) -> Vec<u8> {
        let mut out = if header8 {
            (data.len() as u64).to_le_bytes().to_vec()
        } else {
            (data.len() as u32).to_le_bytes().to_vec()
        };
        out.extend_from_slice(data);
        out
    }

    /// Compressed block split in blocks of `block` bytes; returns (header, zlib data) as VTK does.
    fn zlib_block(data: &[u8], block: usize, header8: bool) -> (Vec<u8>, Vec<u8>) {
        let chunks: Vec<Vec<u8>> = data
            .chunks(block)
            .map(|c| {
                let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                e.write_all(c).unwrap();
                e.finish().unwrap()
            })
            .collect();
        let last = if data.is_empty() { 0 } else { data.len() - (chunks.len() - 1) * block };
        let mut words = vec![chunks.len() as u64, block as u64, last as u64];
        words.extend(chunks.iter().map(|c| c.len() as u64));
        let header = words
            .iter()
            .flat_map(|&w| if header8 { w.to_le_bytes().to_vec() } else { (w as u32).to_le_bytes().to_vec() })
            .collect();
        (header, chunks.concat())
    }

    const PTS: [f32; 12] = [0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.];

    fn file(attrs: &str, arrays: [String; 3], tail: &str) -> String {
        let [points, conn, offs] = arrays;
        format!(
            r#"<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian" {attrs}>
  <PolyData>
    <Piece NumberOfPoints="4" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="1">
      <Points>{points}</Points>
      <Verts>
        <DataArray type="Int64" Name="connectivity" format="ascii"></DataArray>
        <DataArray type="Int64" Name="offsets" format="ascii"/>
      </Verts>
      <Polys>{conn}{offs}</Polys>
    </Piece>
  </PolyData>
{tail}</VTKFile>"#
        )
    }

    fn inline(ty: &str, name: &str, comps: usize, format: &str, body: &str) -> String {
        format!(
            r#"<DataArray type="{ty}" Name="{name}" NumberOfComponents="{comps}" format="{format}">{body}</DataArray>"#
        )
    }

    fn check_quad(pd: &PolyData) {
        assert_eq!(pd.points.len(), 4);
        assert_eq!(pd.points[2], Point3::new(1.0, 1.0, 0.0));
        assert_eq!(pd.polys.len(), 1);
        assert_eq!(pd.polys.cell(0), &[0, 1, 2, 3]);
        assert_eq!(pd.verts.len(), 0);
    }

    #[test]
    fn ascii_arrays() {
        let pts = PTS.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" ");
        let xml = file(
            "",
            [
                inline("Float32", "Points", 3, "ascii", &pts),
                inline("Int32", "connectivity", 1, "ascii", "0 1 2 3"),
                inline("Int32", "offsets", 1, "ascii", "\n 4 \n"),
            ],
            "",
        );
        check_quad(&parse(xml.as_bytes()).unwrap());
    }

    #[test]
    fn base64_uncompressed_both_header_types() {
        for (header8, ht) in [(false, "UInt32"), (true, "UInt64")] {
            let enc = |d: Vec<u8>| b64(&plain_block(&d, header8));
            let xml = file(
                &format!(r#"header_type="{ht}""#),
                [
                    inline("Float32", "Points", 3, "binary", &enc(f32_bytes(&PTS))),
                    inline("Int64", "connectivity", 1, "binary", &enc(i64_bytes(&[0, 1, 2, 3]))),
                    inline("Int64", "offsets", 1, "binary", &enc(i64_bytes(&[4]))),
                ],
                "",
            );
            check_quad(&parse(xml.as_bytes()).unwrap());
        }
    }

    #[test]
    fn base64_zlib_both_header_types() {
        for (header8, ht) in [(false, "UInt32"), (true, "UInt64")] {
            // Blocks of 20 bytes force several blocks with a short last one.
            let enc = |d: Vec<u8>| {
                let (h, z) = zlib_block(&d, 20, header8);
                format!("{}{}", b64(&h), b64(&z))
            };
            let xml = file(
                &format!(r#"header_type="{ht}" compressor="vtkZLibDataCompressor""#),
                [
                    inline("Float32", "Points", 3, "binary", &enc(f32_bytes(&PTS))),
                    inline("Int64", "connectivity", 1, "binary", &enc(i64_bytes(&[0, 1, 2, 3]))),
                    inline("Int64", "offsets", 1, "binary", &enc(i64_bytes(&[4]))),
                ],
                "",
            )
            .replace(
                r#"<DataArray type="Int64" Name="offsets" format="ascii"/>"#,
                &inline("Int64", "offsets", 1, "binary", &enc(Vec::new())),
            );
            check_quad(&parse(xml.as_bytes()).unwrap());
            assert_decoded_size_is_checked(xml.as_bytes(), 88);
        }
    }

    /// The arrays of `bytes` decode to `total` bytes: a limit one byte lower refuses the file
    /// before inflating, the exact total reads it.
    fn assert_decoded_size_is_checked(bytes: &[u8], total: u64) {
        check_quad(&parse_within(bytes, total).unwrap());
        let e = parse_within(bytes, total - 1).unwrap_err();
        assert!(e.contains("decompression bomb"), "{e}");
    }

    fn appended_ref(ty: &str, name: &str, comps: usize, offset: usize) -> String {
        format!(
            r#"<DataArray type="{ty}" Name="{name}" NumberOfComponents="{comps}" format="appended" offset="{offset}"/>"#
        )
    }

    fn appended_arrays(blocks: &[Vec<u8>]) -> [String; 3] {
        let mut offsets = vec![0];
        for b in blocks {
            offsets.push(offsets.last().unwrap() + b.len());
        }
        [
            appended_ref("Float32", "Points", 3, offsets[0]),
            appended_ref("Int64", "connectivity", 1, offsets[1]),
            appended_ref("Int64", "offsets", 1, offsets[2]),
        ]
    }

    #[test]
    fn raw_appended_uint64_header() {
        let blocks = [
            plain_block(&f32_bytes(&PTS), true),
            plain_block(&i64_bytes(&[0, 1, 2, 3]), true),
            plain_block(&i64_bytes(&[4]), true),
        ];
        let xml = file(r#"header_type="UInt64""#, appended_arrays(&blocks), "  <AppendedData encoding=\"raw\">\n   _");
        let mut bytes = xml.into_bytes();
        let tail = bytes.split_off(bytes.len() - "</VTKFile>".len());
        bytes.extend(blocks.concat());
        bytes.extend_from_slice(b"\n  </AppendedData>\n");
        bytes.extend(tail);
        check_quad(&parse(&bytes).unwrap());
    }

    #[test]
    fn base64_appended_zlib() {
        let blocks: Vec<Vec<u8>> = [f32_bytes(&PTS), i64_bytes(&[0, 1, 2, 3]), i64_bytes(&[4])]
            .iter()
            .map(|d| {
                let (h, z) = zlib_block(d, 32768, false);
                format!("{}{}", b64(&h), b64(&z)).into_bytes()
            })
            .collect();
        let text = String::from_utf8(blocks.concat()).unwrap();
        let tail = format!("  <AppendedData encoding=\"base64\">\n   _{text}\n  </AppendedData>\n");
        let xml = file(r#"compressor="vtkZLibDataCompressor""#, appended_arrays(&blocks), &tail);
        check_quad(&parse(xml.as_bytes()).unwrap());
        assert_decoded_size_is_checked(xml.as_bytes(), 88);
    }

    #[test]
    fn big_endian_values() {
        let v = to_values(&[0x3f, 0x80, 0, 0, 0xff, 0xff, 0xff, 0xfe], Scalar::F32, true).unwrap();
        assert_eq!(v.to_f64()[0], 1.0);
        let v = to_values(&[0xff, 0xff, 0xff, 0xfe], Scalar::I32, true).unwrap();
        assert_eq!(v, Values::Int(vec![-2]));
    }

    #[test]
    fn chunked_base64() {
        let joined = format!("{}{}", b64(b"ab"), b64(b"cdef"));
        assert_eq!(decode_base64(joined.as_bytes()).unwrap(), b"abcdef");
        assert!(decode_base64(b"@@@").is_err());
    }

    #[test]
    fn errors_are_clear() {
        let truncated = plain_block(&f32_bytes(&PTS), false);
        let e = unpack(&truncated[..20], Binary { big_endian: false, header_size: 4, compressed: false }).unwrap_err();
        assert!(e.contains("truncated"), "{e}");
        let e = parse(b"<VTKFile type=\"UnstructuredGrid\"></VTKFile>").unwrap_err();
        assert!(e.contains("not PolyData"), "{e}");
        let e = parse(b"<VTKFile type=\"PolyData\"><PolyData><Piece NumberOfPoints=\"3\"/></PolyData></VTKFile>")
            .unwrap_err();
        assert!(e.contains("no <Points>"), "{e}");
        assert!(parse(b"<VTKFile type=\"PolyData\"><PolyData><Piece").is_err());
    }
}
