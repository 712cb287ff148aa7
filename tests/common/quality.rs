//! Shared helpers for the quality / render / eval tests: small mesh generators
//! (open grid, closed torus, hand-made cube), rigid motions, a tiny JSON parser and a
//! tiny XML well-formedness checker (written here so tests need no dependency).
//! Include with `#[path = "common/quality.rs"] mod quality_common;`.
#![allow(dead_code)]

use point2quad::mesh::poly::PolyMesh;

/// An open nu × nv grid of unit quads in the z = 0 plane, counter-clockwise seen from +z;
/// vertex (i, j) is (nu + 1) j + i.
pub fn grid(nu: u32, nv: u32) -> PolyMesh {
    PolyMesh::from(&point2quad::mesh::shapes::grid(nu as usize, nv as usize, nu as f64, nv as f64))
}

/// A closed torus of nu × nv quads (major radius 1, minor r), outward-facing.
pub fn torus(nu: u32, nv: u32, r: f64) -> PolyMesh {
    use std::f64::consts::TAU;
    let mut vertices = Vec::new();
    for j in 0..nv {
        let v = TAU * j as f64 / nv as f64;
        for i in 0..nu {
            let u = TAU * i as f64 / nu as f64;
            let rr = 1.0 + r * v.cos();
            vertices.push([rr * u.cos(), r * v.sin(), rr * u.sin()]);
        }
    }
    let id = |i: u32, j: u32| (j % nv) * nu + (i % nu);
    let mut faces = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            faces.push(vec![id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)]);
        }
    }
    PolyMesh { vertices, faces }
}

/// Closed unit cube offset by `o`, outward-facing quads.
pub fn cube(o: [f64; 3]) -> PolyMesh {
    let vertices = (0..8)
        .map(|i| [o[0] + (i & 1) as f64, o[1] + ((i >> 1) & 1) as f64, o[2] + ((i >> 2) & 1) as f64])
        .collect();
    let faces = vec![
        vec![0, 2, 3, 1],
        vec![4, 5, 7, 6],
        vec![0, 1, 5, 4],
        vec![2, 6, 7, 3],
        vec![0, 4, 6, 2],
        vec![1, 3, 7, 5],
    ];
    PolyMesh { vertices, faces }
}

/// p ↦ s·R·p + t.
pub fn transform(m: &PolyMesh, r: &[[f64; 3]; 3], s: f64, t: [f64; 3]) -> PolyMesh {
    let vertices = m
        .vertices
        .iter()
        .map(|p| {
            let q = point2quad::math::mat_vec(r, *p);
            [s * q[0] + t[0], s * q[1] + t[1], s * q[2] + t[2]]
        })
        .collect();
    PolyMesh { vertices, faces: m.faces.clone() }
}

/// Writes `m` as an OBJ file (1-based indices, full f64 precision).
pub fn write_obj(path: &std::path::Path, m: &PolyMesh) {
    let mut s = String::new();
    for p in &m.vertices {
        s.push_str(&format!("v {:?} {:?} {:?}\n", p[0], p[1], p[2]));
    }
    for f in &m.faces {
        s.push('f');
        for v in f {
            s.push_str(&format!(" {}", v + 1));
        }
        s.push('\n');
    }
    std::fs::write(path, s).expect("test: write obj");
}

/// A parsed JSON value.
#[derive(Clone, Debug, PartialEq)]
pub enum Json {
    Null,
    Bool(bool),
    Num(f64),
    Str(String),
    Arr(Vec<Json>),
    Obj(Vec<(String, Json)>),
}

impl Json {
    /// The value of `key` in an object.
    pub fn get(&self, key: &str) -> Option<&Json> {
        match self {
            Json::Obj(kv) => kv.iter().find(|(k, _)| k == key).map(|(_, v)| v),
            _ => None,
        }
    }
    /// The number, if this is one.
    pub fn num(&self) -> Option<f64> {
        match self {
            Json::Num(x) => Some(*x),
            _ => None,
        }
    }
}

/// Parses one complete JSON document (strict: no trailing garbage, no NaN/Infinity).
pub fn parse_json(s: &str) -> Result<Json, String> {
    let b = s.as_bytes();
    let mut i = 0;
    let v = value(b, &mut i)?;
    ws(b, &mut i);
    if i != b.len() {
        return Err(format!("trailing characters at {i}"));
    }
    Ok(v)
}

fn ws(b: &[u8], i: &mut usize) {
    while *i < b.len() && matches!(b[*i], b' ' | b'\t' | b'\n' | b'\r') {
        *i += 1;
    }
}

fn value(b: &[u8], i: &mut usize) -> Result<Json, String> {
    ws(b, i);
    match b.get(*i) {
        None => Err("unexpected end".into()),
        Some(b'{') => {
            *i += 1;
            let mut kv = Vec::new();
            ws(b, i);
            if b.get(*i) == Some(&b'}') {
                *i += 1;
                return Ok(Json::Obj(kv));
            }
            loop {
                ws(b, i);
                let Json::Str(k) = string(b, i)? else { unreachable!() };
                ws(b, i);
                if b.get(*i) != Some(&b':') {
                    return Err(format!("expected ':' at {i}"));
                }
                *i += 1;
                let v = value(b, i)?;
                if kv.iter().any(|(k2, _): &(String, Json)| *k2 == k) {
                    return Err(format!("duplicate key {k}"));
                }
                kv.push((k, v));
                ws(b, i);
                match b.get(*i) {
                    Some(b',') => *i += 1,
                    Some(b'}') => {
                        *i += 1;
                        return Ok(Json::Obj(kv));
                    }
                    _ => return Err(format!("expected ',' or '}}' at {i}")),
                }
            }
        }
        Some(b'[') => {
            *i += 1;
            let mut items = Vec::new();
            ws(b, i);
            if b.get(*i) == Some(&b']') {
                *i += 1;
                return Ok(Json::Arr(items));
            }
            loop {
                items.push(value(b, i)?);
                ws(b, i);
                match b.get(*i) {
                    Some(b',') => *i += 1,
                    Some(b']') => {
                        *i += 1;
                        return Ok(Json::Arr(items));
                    }
                    _ => return Err(format!("expected ',' or ']' at {i}")),
                }
            }
        }
        Some(b'"') => string(b, i),
        Some(b't') if b[*i..].starts_with(b"true") => {
            *i += 4;
            Ok(Json::Bool(true))
        }
        Some(b'f') if b[*i..].starts_with(b"false") => {
            *i += 5;
            Ok(Json::Bool(false))
        }
        Some(b'n') if b[*i..].starts_with(b"null") => {
            *i += 4;
            Ok(Json::Null)
        }
        Some(_) => number(b, i),
    }
}

fn string(b: &[u8], i: &mut usize) -> Result<Json, String> {
    if b.get(*i) != Some(&b'"') {
        return Err(format!("expected string at {i}"));
    }
    *i += 1;
    let start = *i;
    while *i < b.len() && b[*i] != b'"' {
        if b[*i] == b'\\' {
            *i += 1;
        }
        *i += 1;
    }
    if *i >= b.len() {
        return Err("unterminated string".into());
    }
    let s = String::from_utf8(b[start..*i].to_vec()).map_err(|e| e.to_string())?;
    *i += 1;
    Ok(Json::Str(s))
}

/// JSON number grammar: -? (0 | [1-9][0-9]*) (. [0-9]+)? ([eE] [+-]? [0-9]+)?
fn number(b: &[u8], i: &mut usize) -> Result<Json, String> {
    let start = *i;
    let digits = |i: &mut usize| {
        let s = *i;
        while *i < b.len() && b[*i].is_ascii_digit() {
            *i += 1;
        }
        *i - s
    };
    if b.get(*i) == Some(&b'-') {
        *i += 1;
    }
    let int_start = *i;
    let n = digits(i);
    if n == 0 || (n > 1 && b[int_start] == b'0') {
        return Err(format!("bad number at {start}"));
    }
    if b.get(*i) == Some(&b'.') {
        *i += 1;
        if digits(i) == 0 {
            return Err(format!("bad fraction at {start}"));
        }
    }
    if matches!(b.get(*i), Some(b'e' | b'E')) {
        *i += 1;
        if matches!(b.get(*i), Some(b'+' | b'-')) {
            *i += 1;
        }
        if digits(i) == 0 {
            return Err(format!("bad exponent at {start}"));
        }
    }
    let text = std::str::from_utf8(&b[start..*i]).map_err(|e| e.to_string())?;
    text.parse::<f64>().map(Json::Num).map_err(|e| format!("{text}: {e}"))
}

/// Checks XML well-formedness at the level SVG output needs: an optional prolog,
/// comments, exactly one root element, balanced and properly nested tags, quoted
/// attributes, no stray '<' or '&'. Returns the element names in document order.
pub fn check_xml(s: &str) -> Result<Vec<String>, String> {
    let mut stack: Vec<String> = Vec::new();
    let mut names = Vec::new();
    let mut roots = 0;
    let mut rest = s.trim_start();
    if let Some(r) = rest.strip_prefix("<?xml") {
        let end = r.find("?>").ok_or("unterminated prolog")?;
        rest = &r[end + 2..];
    }
    loop {
        let lt = match rest.find('<') {
            Some(p) => p,
            None => {
                if !stack.is_empty() {
                    return Err(format!("unclosed <{}>", stack.last().unwrap()));
                }
                if !rest.trim().is_empty() {
                    return Err("text after the root".into());
                }
                break;
            }
        };
        let text = &rest[..lt];
        if stack.is_empty() && !text.trim().is_empty() {
            return Err(format!("text outside the root: {:?}", text.trim()));
        }
        if text.contains('&') && !text.contains("&amp;") && !text.contains("&lt;") && !text.contains("&gt;") {
            return Err("bare '&' in text".into());
        }
        rest = &rest[lt..];
        if let Some(r) = rest.strip_prefix("<!--") {
            let end = r.find("-->").ok_or("unterminated comment")?;
            rest = &r[end + 3..];
            continue;
        }
        let gt = rest.find('>').ok_or("unterminated tag")?;
        let tag = &rest[1..gt];
        rest = &rest[gt + 1..];
        if tag.contains('<') {
            return Err(format!("'<' inside tag {tag:?}"));
        }
        if let Some(name) = tag.strip_prefix('/') {
            match stack.pop() {
                Some(open) if open == name.trim() => {}
                other => return Err(format!("</{name}> closes {other:?}")),
            }
            continue;
        }
        let self_closing = tag.ends_with('/');
        let body = tag.trim_end_matches('/');
        let name: String = body.chars().take_while(|c| !c.is_whitespace()).collect();
        if name.is_empty()
            || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == ':' || c == '-' || c == '_')
        {
            return Err(format!("bad element name in {tag:?}"));
        }
        check_attributes(&body[name.len()..])?;
        if stack.is_empty() {
            roots += 1;
            if roots > 1 {
                return Err("more than one root element".into());
            }
        }
        names.push(name.clone());
        if !self_closing {
            stack.push(name);
        }
    }
    if roots != 1 {
        return Err("no root element".into());
    }
    Ok(names)
}

fn check_attributes(mut a: &str) -> Result<(), String> {
    loop {
        a = a.trim_start();
        if a.is_empty() {
            return Ok(());
        }
        let eq = a.find('=').ok_or_else(|| format!("attribute without value: {a:?}"))?;
        let key = a[..eq].trim();
        if key.is_empty() || key.contains(char::is_whitespace) {
            return Err(format!("bad attribute name {key:?}"));
        }
        let v = a[eq + 1..].trim_start();
        let q = v.chars().next().ok_or("missing attribute value")?;
        if q != '"' && q != '\'' {
            return Err(format!("unquoted attribute {key}"));
        }
        let end = v[1..].find(q).ok_or("unterminated attribute value")?;
        a = &v[end + 2..];
    }
}

/// The values of attribute `key` on every element named `name` (a simple scan).
pub fn attr_values(svg: &str, name: &str, key: &str) -> Vec<String> {
    let open = format!("<{name} ");
    let pat = format!(" {key}=\"");
    svg.split(&open)
        .skip(1)
        .filter_map(|el| {
            let el = format!(" {}", &el[..el.find('>').unwrap_or(el.len())]);
            let start = el.find(&pat)? + pat.len();
            Some(el[start..start + el[start..].find('"')?].to_string())
        })
        .collect()
}

#[test]
fn json_parser_accepts_and_rejects() {
    let v = parse_json(r#" {"a": 1, "b": [true, null, -2.5e-3], "c": "x"} "#).unwrap();
    assert_eq!(v.get("a").and_then(Json::num), Some(1.0));
    assert_eq!(v.get("b"), Some(&Json::Arr(vec![Json::Bool(true), Json::Null, Json::Num(-2.5e-3)])));
    for bad in
        ["{", "{\"a\": NaN}", "{\"a\": 01}", "{\"a\": 1} x", "{\"a\": 1, \"a\": 2}", "{\"a\": inf}", "[1,]"]
    {
        assert!(parse_json(bad).is_err(), "{bad}");
    }
}

#[test]
fn xml_checker_accepts_and_rejects() {
    assert!(
        check_xml("<?xml version=\"1.0\"?>\n<svg a=\"1\"><g><line x=\"2\"/></g><!-- c --></svg>\n").is_ok()
    );
    for bad in
        ["<svg><g></svg>", "<svg></svg><svg></svg>", "<svg a=1></svg>", "text<svg/>", "<svg><g></g>", ""]
    {
        assert!(check_xml(bad).is_err(), "{bad}");
    }
}
