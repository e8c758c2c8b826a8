//! Checks that a `#[repr(C)]` struct shared with WGSL has the layout the shader sees, and that
//! a Rust enum's codes equal the shader's constants: the shader source is parsed by naga (the
//! compiler wgpu itself uses), so the offsets compared are the ones the GPU reads, not a copy.
//!
//! Use [`wgsl_layout!`](crate::wgsl_layout) in a test beside the struct; a mismatch names the
//! struct, the field and both offsets.

use wgpu::naga;

/// Parses `wgsl` (a whole module: prelude files joined with the pass's file).
fn parse(wgsl: &str) -> Result<naga::Module, String> {
    naga::front::wgsl::parse_str(wgsl).map_err(|e| e.emit_to_string(wgsl))
}

/// Compares WGSL struct `name` in `wgsl` with a Rust struct of `size` bytes whose fields, in
/// declaration order, are `fields` (name, `offset_of!`). Names, order, offsets and the size (the
/// array stride the shader uses) must all agree.
pub fn check_struct(wgsl: &str, name: &str, size: usize, fields: &[(&str, usize)]) -> Result<(), String> {
    let module = parse(wgsl)?;
    let (members, span) = module
        .types
        .iter()
        .find_map(|(_, t)| match (&t.name, &t.inner) {
            (Some(n), naga::TypeInner::Struct { members, span }) if n == name => Some((members, *span)),
            _ => None,
        })
        .ok_or_else(|| format!("no struct {name} in the WGSL"))?;
    let wgsl_fields: Vec<(String, usize)> = members
        .iter()
        .map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize))
        .collect();
    let rust_fields: Vec<(String, usize)> = fields.iter().map(|(n, o)| (n.to_string(), *o)).collect();
    if wgsl_fields != rust_fields {
        return Err(format!(
            "struct {name}: WGSL fields (name, offset) {wgsl_fields:?} differ from Rust {rust_fields:?}"
        ));
    }
    // The array stride of a struct is its size rounded up to its alignment; naga's span is that.
    if span as usize != size {
        return Err(format!("struct {name}: {span} bytes in WGSL, {size} in Rust"));
    }
    Ok(())
}

/// The value of WGSL `const name: u32` (or an `i32`/abstract integer that fits) in `wgsl`.
pub fn wgsl_const(wgsl: &str, name: &str) -> Result<i64, String> {
    let module = parse(wgsl)?;
    let (_, c) = module
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
        .ok_or_else(|| format!("no const {name} in the WGSL"))?;
    match module.global_expressions[c.init] {
        naga::Expression::Literal(naga::Literal::U32(v)) => Ok(v as i64),
        naga::Expression::Literal(naga::Literal::I32(v)) => Ok(v as i64),
        naga::Expression::Literal(naga::Literal::AbstractInt(v)) => Ok(v),
        ref e => Err(format!("const {name} is not an integer literal ({e:?})")),
    }
}

/// Checks `wgsl_const(wgsl, name) == value` for every pair, naming the first that differs.
pub fn check_consts(wgsl: &str, pairs: &[(&str, i64)]) -> Result<(), String> {
    for (name, value) in pairs {
        let found = wgsl_const(wgsl, name)?;
        if found != *value {
            return Err(format!("WGSL const {name} = {found}, Rust says {value}"));
        }
    }
    Ok(())
}

/// `check_struct` for a Rust type and its field names:
/// `wgsl_layout!(SOURCE, GpuLight, "Light", [kind, first_view, position])` returns
/// `Result<(), String>`.
#[macro_export]
macro_rules! wgsl_layout {
    ($wgsl:expr, $ty:ty, $name:expr, [$($field:ident),* $(,)?]) => {
        $crate::layout::check_struct(
            $wgsl,
            $name,
            ::std::mem::size_of::<$ty>(),
            &[$((stringify!($field), ::std::mem::offset_of!($ty, $field))),*],
        )
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[repr(C)]
    struct Pair {
        a: u32,
        b: [f32; 4],
    }

    const SRC: &str = "struct Pair { a: u32, b: vec4<f32> };\nconst KIND_TWO: u32 = 2u;\n\
        @group(0) @binding(0) var<storage> p: array<Pair>;\n@compute @workgroup_size(1) fn main() { _ = p[0].a + KIND_TWO; }";

    #[test]
    fn a_padded_member_is_caught_with_both_offsets() {
        // vec4 aligns to 16 in WGSL: b sits at 16, the Rust struct has it at 4.
        let e = wgsl_layout!(SRC, Pair, "Pair", [a, b]).unwrap_err();
        assert!(e.contains("(\"b\", 16)") && e.contains("(\"b\", 4)"), "{e}");
    }

    #[test]
    fn matching_layouts_and_consts_pass_and_wrong_ones_fail() {
        #[repr(C)]
        struct Padded {
            a: u32,
            _pad: [u32; 3],
            b: [f32; 4],
        }
        let src = "struct Padded { a: u32, _pad: vec3<u32>, b: vec4<f32> };";
        // vec3<u32> aligns to 16: _pad lands at 16, not 4.
        assert!(wgsl_layout!(src, Padded, "Padded", [a, _pad, b]).is_err());
        let src = "struct Padded { a: u32, _pad0: u32, _pad1: u32, _pad2: u32, b: vec4<f32> };";
        assert!(
            wgsl_layout!(src, Padded, "Padded", [a, _pad, b]).is_err(),
            "names must agree"
        );
        assert!(check_struct(
            src,
            "Padded",
            32,
            &[("a", 0), ("_pad0", 4), ("_pad1", 8), ("_pad2", 12), ("b", 16)]
        )
        .is_ok());
        assert_eq!(wgsl_const(SRC, "KIND_TWO"), Ok(2));
        assert!(check_consts(SRC, &[("KIND_TWO", 3)]).is_err());
        assert!(wgsl_const(SRC, "MISSING").is_err());
    }
}
