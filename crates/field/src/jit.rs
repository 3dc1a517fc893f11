//! The tape compiled to machine code per program: 8-lane evaluation of a [`Tape`] as one
//! straight-line function generated with cranelift.
//!
//! A [`crate::kernel::Kernel`] removes the tape's per-leaf dispatch but keeps a loop over
//! runs of leaves, the running minimum in an `Option` and register spills around them:
//! about 140 of its ~239 instructions per evaluation on `seed-spheres` (callgrind) are that
//! bookkeeping. A [`Jit`] removes it: the program's leaves, frames, running minimum and root
//! bound become one function of the eight points, every constant an operand read from a
//! table the function is given.
//!
//! # Bit for bit the tape, by construction
//! The code is not written a second time: the tape's own evaluation (the root's bound, each
//! leaf through `tape::bounded` and [`crate::leaf::Leaf`]'s distance, the running minimum,
//! the scales) is run once on a symbolic lane type (`Sym`) whose arithmetic records each
//! operation instead of computing it, so the recorded trace is the tape's operations in the
//! tape's order, and is then lowered one for one to cranelift instructions:
//! - `+ - * /`, square root, absolute value and negation are IEEE operations in both (and
//!   cranelift never fuses a multiply and an add unless asked to);
//! - every `min`/`max` is the interpreter's compare-and-select (`a < b ? a : b`,
//!   `a > b ? a : b`), emitted as a compare and a bit select (which the x64 backend turns
//!   into `minps`/`maxps`, whose semantics are exactly these); cranelift's own `fmin`/`fmax`
//!   differ on NaN and signed zeros and are never used;
//! - the evaluation's shortcuts taken when every lane agrees (`Lane::all`: a bounded leaf
//!   skipped by all lanes, a triangle's inside test) answer "no" while tracing, so the
//!   function computes both sides and selects per lane: the values the shortcut would
//!   return. The root's bound keeps its shortcut as a real branch (most lanes of a ray
//!   far from the scene take it).
//!
//! Cranelift's x64 backend has no 256-bit vectors: the eight lanes are two halves of four,
//! each half's operations emitted in turn.
//!
//! Compiled: every tape without mesh grids and without a root union of two bounded members
//! (the tape orders those by a horizontal sum, a decision the trace cannot take), as
//! [`crate::kernel::Kernel`]. A tape the trace cannot follow, or a cranelift error, is an
//! error ([`JitError`]), never a panic: the caller keeps the kernel or the tape.
//!
//! The lowering needs the crate's cargo feature `jit` (off by default: cranelift doubles the
//! crate's cold build, and on x64 the compiled function is slower than the kernel,
//! `docs/decisions/0026-field-programs-compiled-with-cranelift.md`); without it the trace is
//! built and [`Jit::of`] is an error.
//!
//! The one module of the crate that allows `unsafe` code: calling the generated function
//! (and freeing its memory). Its memory contract: it reads 24 f32 (the points' x, y and z
//! lanes) from its first argument and the constant table from its second, writes 8 f32 to
//! its third, and touches nothing else (no calls, no stack arguments).
#![allow(unsafe_code)]
// Without the `jit` feature the trace is kept (and tested) but nothing lowers it.
#![cfg_attr(not(feature = "jit"), allow(dead_code))]

use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

#[cfg(feature = "jit")]
use cranelift_codegen::ir::condcodes::FloatCC;
#[cfg(feature = "jit")]
use cranelift_codegen::ir::{AbiParam, InstBuilder, MemFlagsData, Value, types};
#[cfg(feature = "jit")]
use cranelift_codegen::settings::{self, Configurable};
#[cfg(feature = "jit")]
use cranelift_codegen::{Context, isa};
#[cfg(feature = "jit")]
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
#[cfg(feature = "jit")]
use cranelift_jit::{JITBuilder, JITModule};
#[cfg(feature = "jit")]
use cranelift_module::{Linkage, Module};

use crate::lane::{F32x8, Lane, V3};
use crate::leaf::NoGrids;
use crate::program::GridSampler;
use crate::shapes;
use crate::tape::{Tape, TapeLeaf, bounded};

/// Why a tape was not compiled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JitError {
    /// The tape has a shape the trace cannot follow (mesh grids, a root union of two
    /// bounded members): the kernel or the tape evaluates it.
    #[error("not compiled: {0}")]
    Unsupported(&'static str),
    /// Cranelift could not build the host's code generator or compile the function.
    #[error("cranelift: {0}")]
    Codegen(String),
}

/// One recorded operation; operands are indices of earlier operations.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Op {
    /// Coordinate `k` of the points (0: x, 1: y, 2: z).
    Input(u8),
    /// A constant in every lane.
    Const(f32),
    Add(u32, u32),
    Sub(u32, u32),
    Mul(u32, u32),
    Div(u32, u32),
    Neg(u32),
    Sqrt(u32),
    Abs(u32),
    /// `a < b ? a : b`.
    Min(u32, u32),
    /// `a > b ? a : b`.
    Max(u32, u32),
    /// Mask `a < b`.
    Lt(u32, u32),
    /// Mask `a <= b`.
    Le(u32, u32),
    And(u32, u32),
    Or(u32, u32),
    Not(u32),
    /// `m ? a : b`.
    Select(u32, u32, u32),
    /// Return value `v` when every lane of mask `m` is set.
    ExitIfAll(u32, u32),
}

/// The operations recorded so far on this thread, and the first thing the trace could not
/// follow.
#[derive(Default)]
struct Trace {
    ops: Vec<Op>,
    unsupported: Option<&'static str>,
}

thread_local! {
    static TRACE: RefCell<Trace> = RefCell::new(Trace::default());
}

fn record(op: Op) -> u32 {
    TRACE.with(|t| {
        let mut t = t.borrow_mut();
        t.ops.push(op);
        (t.ops.len() - 1) as u32
    })
}

fn unsupported(what: &'static str) {
    TRACE.with(|t| {
        t.borrow_mut().unsupported.get_or_insert(what);
    });
}

/// A symbolic lane value: the index of the operation that computes it in this thread's
/// trace. Its [`Lane`] arithmetic records operations.
#[derive(Debug, Clone, Copy)]
struct Sym(u32);

/// A symbolic mask.
#[derive(Debug, Clone, Copy)]
struct SymMask(u32);

macro_rules! sym_binop {
    ($tr:ident, $f:ident, $op:ident) => {
        impl std::ops::$tr for Sym {
            type Output = Sym;
            fn $f(self, o: Sym) -> Sym {
                Sym(record(Op::$op(self.0, o.0)))
            }
        }
    };
}
sym_binop!(Add, add, Add);
sym_binop!(Sub, sub, Sub);
sym_binop!(Mul, mul, Mul);
sym_binop!(Div, div, Div);

impl std::ops::Neg for Sym {
    type Output = Sym;
    fn neg(self) -> Sym {
        Sym(record(Op::Neg(self.0)))
    }
}

impl Lane for Sym {
    type S = f32;
    type Mask = SymMask;
    type Mat = ();
    fn splat(s: f32) -> Self {
        Sym(record(Op::Const(s)))
    }
    fn sqrt(self) -> Self {
        Sym(record(Op::Sqrt(self.0)))
    }
    fn abs(self) -> Self {
        Sym(record(Op::Abs(self.0)))
    }
    fn min(self, o: Self) -> Self {
        Sym(record(Op::Min(self.0, o.0)))
    }
    fn max(self, o: Self) -> Self {
        Sym(record(Op::Max(self.0, o.0)))
    }
    fn floor(self) -> Self {
        unsupported("floor");
        self
    }
    fn ceil(self) -> Self {
        unsupported("ceil");
        self
    }
    fn lt(self, o: Self) -> SymMask {
        SymMask(record(Op::Lt(self.0, o.0)))
    }
    fn le(self, o: Self) -> SymMask {
        SymMask(record(Op::Le(self.0, o.0)))
    }
    fn and(a: SymMask, b: SymMask) -> SymMask {
        SymMask(record(Op::And(a.0, b.0)))
    }
    fn or(a: SymMask, b: SymMask) -> SymMask {
        SymMask(record(Op::Or(a.0, b.0)))
    }
    fn not(m: SymMask) -> SymMask {
        SymMask(record(Op::Not(m.0)))
    }
    fn any(_: SymMask) -> bool {
        unsupported("a branch on any lane");
        false
    }
    /// "Not every lane": the evaluations branch on `all` only for shortcuts whose value
    /// the other side's per-lane select also gives (see the module docs).
    fn all(_: SymMask) -> bool {
        false
    }
    fn select(m: SymMask, a: Self, b: Self) -> Self {
        Sym(record(Op::Select(m.0, a.0, b.0)))
    }
    fn mat_splat(_: u32) {}
    fn mat_select(_: SymMask, _: (), _: ()) {}
    fn hmax(self) -> f64 {
        unsupported("a horizontal maximum");
        0.0
    }
    fn hsum(self) -> f64 {
        unsupported("a horizontal sum");
        0.0
    }
    fn sample_grid(_: &dyn GridSampler, x: Self, _: Self, _: Self) -> Self {
        unsupported("a mesh grid");
        x
    }
}

/// The tape's 8-lane distance evaluation (`Tape::eval::<F32x8, false>` without materials)
/// recorded on symbolic lanes: the same steps as `Tape::eval_in` and `Tape::union` for a
/// tape without a pair root.
fn trace(tape: &Tape) -> Result<(Vec<Op>, u32), JitError> {
    if tape.has_mesh {
        return Err(JitError::Unsupported("mesh grids"));
    }
    if tape.leaves.is_empty() {
        return Err(JitError::Unsupported("an empty tape"));
    }
    if tape.root.as_ref().is_some_and(|r| r.pair) {
        return Err(JitError::Unsupported("a root union of two bounded members"));
    }
    TRACE.with(|t| *t.borrow_mut() = Trace::default());
    let p = V3::new(
        Sym(record(Op::Input(0))),
        Sym(record(Op::Input(1))),
        Sym(record(Op::Input(2))),
    );
    let leaf = |l: &TapeLeaf, q: V3<Sym>, below: Option<Sym>| {
        bounded::<Sym, false, NoGrids>(l, q, below, NoGrids).0
    };
    let out = match &tape.root {
        None => leaf(&tape.leaves[0], p, None),
        Some(root) => {
            let union = || {
                let q = root.to_local.apply(p);
                let ds = Sym::splat(root.dscale);
                let mut best = leaf(&tape.leaves[0], q, None);
                for l in &tape.leaves[1..] {
                    let d = leaf(l, q, Some(best));
                    best = best.min(d);
                }
                best * ds
            };
            match &root.bound {
                None => union(),
                Some(b) => {
                    let zero = Sym::c(0.0);
                    let l = shapes::box_distance(p, V3::splat3(b.lo), V3::splat3(b.hi));
                    let tau = Sym::splat(b.tau);
                    let outside = Sym::lt(zero, l);
                    let skip = Sym::and(outside, Sym::le(tau, l));
                    record(Op::ExitIfAll(skip.0, l.0));
                    let c = union();
                    let cc = c.min(tau);
                    let g = Sym::select(outside, l.max(cc), cc);
                    Sym::select(skip, l, g)
                }
            }
        }
    };
    let t = TRACE.with(|t| std::mem::take(&mut *t.borrow_mut()));
    if let Some(what) = t.unsupported {
        return Err(JitError::Unsupported(what));
    }
    Ok((t.ops, out.0))
}

/// Eight f32 lanes at a 32-byte boundary (the layout the generated code reads and writes).
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(32))]
struct Slot([f32; 8]);

/// The generated function: points (3 slots: x, y, z), constant table, result (1 slot).
#[cfg(feature = "jit")]
type Func = unsafe extern "C" fn(*const Slot, *const Slot, *mut Slot);

/// A [`Tape`] compiled to a straight-line function, see the [module docs](self).
pub struct Jit {
    #[cfg(feature = "jit")]
    func: Func,
    /// Without the `jit` feature no `Jit` exists.
    #[cfg(not(feature = "jit"))]
    never: std::convert::Infallible,
    /// The function's constants, one slot per recorded constant.
    consts: Box<[Slot]>,
    /// Operations recorded (for reports).
    ops: usize,
    /// The module owning the code (freed on drop); behind a mutex only so that `Jit` is
    /// `Sync` (it is never locked while evaluating).
    #[cfg(feature = "jit")]
    module: Mutex<Option<JITModule>>,
}

impl std::fmt::Debug for Jit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Jit")
            .field("ops", &self.ops)
            .field("consts", &self.consts.len())
            .finish()
    }
}

#[cfg(feature = "jit")]
impl Drop for Jit {
    fn drop(&mut self) {
        let module = self.module.get_mut().ok().and_then(Option::take);
        if let Some(m) = module {
            // SAFETY: `func` points into this module's memory and is only reachable
            // through `self`, which is being dropped: nothing can call it afterwards.
            unsafe { m.free_memory() };
        }
    }
}

impl Jit {
    /// The tape compiled for the host CPU; an error when the tape has a shape the trace
    /// cannot follow or cranelift fails (a panic inside cranelift is caught and reported
    /// as an error too).
    pub fn of(tape: &Tape) -> Result<Jit, JitError> {
        let (ops, out) = trace(tape)?;
        #[cfg(feature = "jit")]
        {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| compile(&ops, out)))
                .unwrap_or_else(|_| Err(JitError::Codegen("cranelift panicked".into())))
        }
        #[cfg(not(feature = "jit"))]
        {
            let _ = (ops, out);
            Err(JitError::Unsupported(
                "built without the field crate's `jit` feature",
            ))
        }
    }

    /// Operations of the compiled trace.
    pub fn ops(&self) -> usize {
        self.ops
    }

    /// The distances at eight points, bit for bit [`Tape::eval`]'s on the tape the
    /// function was compiled from.
    #[cfg_attr(not(debug_assertions), inline)]
    #[cfg(not(feature = "jit"))]
    pub fn eval(&self, _: V3<F32x8>) -> F32x8 {
        match self.never {}
    }

    /// The distances at eight points, bit for bit [`Tape::eval`]'s on the tape the
    /// function was compiled from.
    #[cfg(feature = "jit")]
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn eval(&self, p: V3<F32x8>) -> F32x8 {
        let input = [Slot(p.x.0), Slot(p.y.0), Slot(p.z.0)];
        let mut out = Slot::default();
        // SAFETY: the function was generated by `compile` for the host's ISA and calling
        // convention with this signature; it reads exactly 3 slots from `input`, only slots
        // below `consts.len()` from `consts` (the table it was compiled with, owned by
        // `self`), writes one slot to `out`, and its code lives as long as `self.module`.
        unsafe { (self.func)(input.as_ptr(), self.consts.as_ptr(), &mut out) };
        F32x8(out.0)
    }
}

#[cfg(feature = "jit")]
/// The host's code generator.
fn host_isa() -> Result<isa::OwnedTargetIsa, JitError> {
    let err = |e: &dyn std::fmt::Display| JitError::Codegen(e.to_string());
    let mut flags = settings::builder();
    for (k, v) in [
        ("opt_level", "speed"),
        ("is_pic", "false"),
        ("use_colocated_libcalls", "false"),
        (
            "enable_verifier",
            if cfg!(debug_assertions) {
                "true"
            } else {
                "false"
            },
        ),
    ] {
        flags.set(k, v).map_err(|e| err(&e))?;
    }
    let builder = cranelift_native::builder().map_err(|e| err(&e))?;
    builder
        .finish(settings::Flags::new(flags))
        .map_err(|e| err(&e))
}

#[cfg(feature = "jit")]
/// Lowers a trace to a function of the host (two halves of four lanes).
fn compile(ops: &[Op], result: u32) -> Result<Jit, JitError> {
    let err = |e: &dyn std::fmt::Display| JitError::Codegen(e.to_string());
    let isa = host_isa()?;
    let ptr = isa.pointer_type();
    let frontend = isa.frontend_config();
    let mut module = JITModule::new(JITBuilder::with_isa(
        isa,
        cranelift_module::default_libcall_names(),
    ));
    let mut ctx: Context = module.make_context();
    for _ in 0..3 {
        ctx.func.signature.params.push(AbiParam::new(ptr));
    }
    let mut fctx = FunctionBuilderContext::new();
    let mut consts: Vec<Slot> = Vec::new();
    {
        let mut b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
        let entry = b.create_block();
        b.append_block_params_for_function_params(entry);
        b.switch_to_block(entry);
        let params = b.block_params(entry).to_vec();
        let (pin, pconst, pout) = (params[0], params[1], params[2]);
        // Aligned (the slots are 32-byte aligned), never trapping (valid for the call).
        let mem = MemFlagsData::trusted();
        let mut val: Vec<[Option<Value>; 2]> = vec![[None, None]; ops.len()];
        // Segments end at each exit: each segment's operations are emitted half by half.
        let mut start = 0;
        let store_ret = |b: &mut FunctionBuilder, v: [Value; 2]| {
            b.ins().store(mem, v[0], pout, 0);
            b.ins().store(mem, v[1], pout, 16);
            b.ins().return_(&[]);
        };
        let get = |val: &Vec<[Option<Value>; 2]>, i: u32, h: usize| -> Result<Value, JitError> {
            val[i as usize][h].ok_or_else(|| JitError::Codegen("operand used before set".into()))
        };
        for end in (0..ops.len()).filter(|&i| matches!(ops[i], Op::ExitIfAll(..))) {
            emit_range(
                &mut b,
                ops,
                start..end,
                &mut val,
                &mut consts,
                (pin, pconst),
            )?;
            let Op::ExitIfAll(m, v) = ops[end] else {
                unreachable!("filtered")
            };
            let (m0, m1) = (get(&val, m, 0)?, get(&val, m, 1)?);
            let both = b.ins().band(m0, m1);
            let all = b.ins().vall_true(both);
            let exit = b.create_block();
            let cont = b.create_block();
            b.ins().brif(all, exit, &[], cont, &[]);
            b.switch_to_block(exit);
            let vv = [get(&val, v, 0)?, get(&val, v, 1)?];
            store_ret(&mut b, vv);
            b.switch_to_block(cont);
            start = end + 1;
        }
        emit_range(
            &mut b,
            ops,
            start..ops.len(),
            &mut val,
            &mut consts,
            (pin, pconst),
        )?;
        let out = [get(&val, result, 0)?, get(&val, result, 1)?];
        store_ret(&mut b, out);
        b.seal_all_blocks();
        b.finalize(frontend);
    }
    let id = module
        .declare_function("field", Linkage::Local, &ctx.func.signature)
        .map_err(|e| err(&e))?;
    module.define_function(id, &mut ctx).map_err(|e| err(&e))?;
    module.clear_context(&mut ctx);
    module.finalize_definitions().map_err(|e| err(&e))?;
    let code = module.get_finalized_function(id);
    // SAFETY: `code` is the finalized entry of the function defined above with signature
    // (ptr, ptr, ptr) -> () in the ISA's default calling convention, which is the C
    // calling convention of the host; it stays valid while `module` is not freed, and
    // `module` is moved into the returned `Jit` that holds the pointer.
    let func = unsafe { std::mem::transmute::<*const u8, Func>(code) };
    Ok(Jit {
        func,
        consts: consts.into_boxed_slice(),
        ops: ops.len(),
        module: Mutex::new(Some(module)),
    })
}

#[cfg(feature = "jit")]
/// Emits operations `range` of the trace, first every lane of the first half, then of the
/// second (inputs and constants loaded where first used).
fn emit_range(
    b: &mut FunctionBuilder,
    ops: &[Op],
    range: std::ops::Range<usize>,
    val: &mut [[Option<Value>; 2]],
    consts: &mut Vec<Slot>,
    (pin, pconst): (Value, Value),
) -> Result<(), JitError> {
    // Read-only and movable: the loads are pure, so each is placed beside its use and
    // becomes the arithmetic instruction's memory operand (loaded up front, the constants
    // filled the registers and spilled).
    let mem = MemFlagsData::trusted().with_readonly().with_can_move();
    let cmem = mem;
    let vflags = MemFlagsData::new().with_endianness(cranelift_codegen::ir::Endianness::Little);
    let f4 = types::F32X4;
    // The constant slot of each constant operation of the range.
    let mut slot = vec![0u32; range.len()];
    for (k, i) in range.clone().enumerate() {
        if let Op::Const(c) = ops[i] {
            slot[k] = consts.len() as u32;
            consts.push(Slot([c; 8]));
        }
    }
    for h in 0..2 {
        for (k, i) in range.clone().enumerate() {
            let g = |j: u32| {
                val[j as usize][h]
                    .ok_or_else(|| JitError::Codegen("operand used before set".into()))
            };
            let off = 16 * h as i32;
            let v = match ops[i] {
                Op::Input(c) => b.ins().load(f4, mem, pin, 32 * i32::from(c) + off),
                Op::Const(_) => b.ins().load(f4, cmem, pconst, 32 * slot[k] as i32 + off),
                Op::Add(x, y) => b.ins().fadd(g(x)?, g(y)?),
                Op::Sub(x, y) => b.ins().fsub(g(x)?, g(y)?),
                Op::Mul(x, y) => b.ins().fmul(g(x)?, g(y)?),
                Op::Div(x, y) => b.ins().fdiv(g(x)?, g(y)?),
                Op::Neg(x) => b.ins().fneg(g(x)?),
                Op::Sqrt(x) => b.ins().sqrt(g(x)?),
                Op::Abs(x) => b.ins().fabs(g(x)?),
                Op::Min(x, y) => {
                    let (x, y) = (g(x)?, g(y)?);
                    let m = b.ins().fcmp(FloatCC::LessThan, x, y);
                    let m = b.ins().bitcast(f4, vflags, m);
                    b.ins().bitselect(m, x, y)
                }
                Op::Max(x, y) => {
                    let (x, y) = (g(x)?, g(y)?);
                    let m = b.ins().fcmp(FloatCC::LessThan, y, x);
                    let m = b.ins().bitcast(f4, vflags, m);
                    b.ins().bitselect(m, x, y)
                }
                Op::Lt(x, y) => b.ins().fcmp(FloatCC::LessThan, g(x)?, g(y)?),
                Op::Le(x, y) => b.ins().fcmp(FloatCC::LessThanOrEqual, g(x)?, g(y)?),
                Op::And(x, y) => b.ins().band(g(x)?, g(y)?),
                Op::Or(x, y) => b.ins().bor(g(x)?, g(y)?),
                Op::Not(x) => b.ins().bnot(g(x)?),
                Op::Select(m, x, y) => {
                    let m = b.ins().bitcast(f4, vflags, g(m)?);
                    b.ins().bitselect(m, g(x)?, g(y)?)
                }
                Op::ExitIfAll(..) => {
                    return Err(JitError::Codegen("an exit inside a segment".into()));
                }
            };
            val[i][h] = Some(v);
        }
    }
    Ok(())
}

/// Compiled restrictions of one field ([`crate::Field::restrict_to`]), keyed by the field's
/// nodes each kept: a bundle of rays whose restriction was seen before reuses its function
/// (a lookup per bundle), a new one is compiled once. At most [`Cache::MAX`] entries; past
/// them new restrictions get no function (the kernel or the tape serves them).
#[derive(Default)]
pub(crate) struct Cache {
    map: Mutex<HashMap<Vec<u32>, Option<Arc<Jit>>>>,
}

impl Cache {
    /// Most restrictions compiled per field.
    pub(crate) const MAX: usize = 256;

    /// The function of the restriction that kept `kept`, whose tape is `tape`: cached, or
    /// compiled now; `None` when it does not compile or the cache is full.
    pub(crate) fn get_or_compile(&self, kept: &[u32], tape: &Tape) -> Option<Arc<Jit>> {
        let mut map = self.map.lock().ok()?;
        if let Some(j) = map.get(kept) {
            return j.clone();
        }
        if map.len() >= Self::MAX {
            return None;
        }
        let j = Jit::of(tape).ok().map(Arc::new);
        map.insert(kept.to_vec(), j.clone());
        j
    }

    /// Restrictions seen (compiled or not).
    pub(crate) fn len(&self) -> usize {
        self.map.lock().map_or(0, |m| m.len())
    }

    /// Forgets every restriction (the field's program changed).
    pub(crate) fn clear(&self) {
        if let Ok(mut m) = self.map.lock() {
            m.clear();
        }
    }
}

#[cfg(test)]
#[cfg_attr(not(feature = "jit"), allow(unused_imports))]
mod tests {
    use super::*;
    use crate::{Field, FieldOptions};
    use glam::{DAffine3, DVec3, Vec3};
    use marchmesh_scene::{Node, NodeKind, Shape, compose_transform};

    fn leaf(shape: Shape, at: DVec3) -> Node {
        Node {
            transform: compose_transform(at, DVec3::new(10.0, 20.0, 0.0), DVec3::ONE),
            material: 1,
            name: None,
            json_path: "t".into(),
            kind: NodeKind::Leaf(shape),
        }
    }

    fn tape_of(n: &Node) -> Tape {
        let f =
            Field::compile_node(n, DAffine3::IDENTITY, &FieldOptions::default()).expect("compiles");
        Tape::of(&f.p32).expect("a tape")
    }

    #[cfg(feature = "jit")]
    /// A union of a sphere and a box, compiled: the tape's bits at ordinary and odd points
    /// (NaN, infinities, signed zeros), inside and outside the root's bound.
    #[test]
    fn bit_for_bit_the_tape() {
        let n = Node {
            transform: DAffine3::IDENTITY,
            material: 0,
            name: None,
            json_path: "t".into(),
            kind: NodeKind::Union(vec![
                leaf(Shape::Sphere { radius: 0.5 }, DVec3::new(-1.0, 0.0, 3.0)),
                leaf(
                    Shape::Box {
                        half_extents: DVec3::new(0.3, 0.4, 0.5),
                    },
                    DVec3::new(1.0, 0.0, 3.0),
                ),
            ]),
        };
        let tape = tape_of(&n);
        let jit = Jit::of(&tape).expect("compiles");
        assert!(jit.ops() > 10);
        let odd = [0.0, -0.0, f32::NAN, f32::INFINITY, -1e30, 0.25, -3.0, 40.0];
        for j in 0..64 {
            let pt = |i: usize| {
                Vec3::new(
                    odd[(i + j) % 8] * (j % 3) as f32 + (i as f32) * 0.3 - 1.0,
                    odd[(i * 3 + j) % 8],
                    3.0 + odd[(i * 5 + j / 8) % 8] * 0.1,
                )
            };
            let p = V3::from_points(std::array::from_fn(pt));
            let want = tape.eval::<F32x8, false>(p, &[]).0;
            let got = jit.eval(p);
            for i in 0..8 {
                assert_eq!(
                    got.0[i].to_bits(),
                    want.0[i].to_bits(),
                    "lane {i} at {}",
                    pt(i)
                );
            }
        }
    }

    /// Tapes the trace cannot follow are errors, not panics.
    #[test]
    fn unsupported_tapes_are_errors() {
        assert!(matches!(
            Jit::of(&Tape::default()),
            Err(JitError::Unsupported(_))
        ));
        let mut t = tape_of(&leaf(Shape::Sphere { radius: 1.0 }, DVec3::ZERO));
        t.has_mesh = true;
        assert!(matches!(Jit::of(&t), Err(JitError::Unsupported(_))));
    }
}
