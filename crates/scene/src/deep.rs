//! Deep object trees without deep stacks.
//!
//! Scene files nest objects as deep as their authors' tools emit them (a left-deep binary
//! tree of N blended primitives is N levels deep). Every recursion over a file's tree
//! (parsing, validation, cloning, comparing, printing) calls [`guard`] once per level: it runs the level on the current stack while more than [`RED_ZONE`]
//! bytes of it are left, and on a fresh heap-allocated segment of [`STACK_SEGMENT`] bytes
//! otherwise (`stacker`, as rustc does for its own deep recursions), so any thread, rayon
//! workers with their small stacks included, walks any depth the limits allow
//! ([`crate::validate::MAX_NESTING_DEPTH`]). Dropping is iterative. Once resolved, chains
//! of one operation are merged and the tree is at most
//! [`crate::validate::MAX_MERGED_DEPTH`] deep, which the backends walk on their callers'
//! stacks.

/// Stack left below which [`guard`] moves to a new segment, bytes: more than any level of
/// any guarded recursion uses between two guards, with room for what the caller runs on
/// top of it.
pub const RED_ZONE: usize = 256 * 1024;

/// Size of each stack segment [`guard`] allocates, bytes.
pub const STACK_SEGMENT: usize = 4 * 1024 * 1024;

/// Runs `f` on the current stack when at least [`RED_ZONE`] bytes of it are left, else on a
/// new heap-allocated stack segment of [`STACK_SEGMENT`] bytes (freed when `f` returns).
#[inline]
pub fn guard<R>(f: impl FnOnce() -> R) -> R {
    stacker::maybe_grow(RED_ZONE, STACK_SEGMENT, f)
}

/// Drops a tree iteratively: `take_children` empties a node of its children (returning
/// them), so no node is dropped while holding a subtree and no drop recurses.
pub(crate) fn drop_tree<N>(children: Vec<N>, take_children: impl Fn(&mut N) -> Vec<N>) {
    let mut stack = children;
    while let Some(mut n) = stack.pop() {
        stack.append(&mut take_children(&mut n));
    }
}

/// The 1-based line and column of the first `{` or `[` of `json` (outside strings) that
/// opens a level deeper than `max_depth`, or `None`. A linear scan without recursion, run
/// before parsing so that no recursion ever sees a deeper document.
pub(crate) fn too_deep(json: &str, max_depth: usize) -> Option<(usize, usize)> {
    let (mut depth, mut line, mut column) = (0usize, 1usize, 0usize);
    let (mut in_string, mut escaped) = (false, false);
    for c in json.chars() {
        column += 1;
        if c == '\n' {
            line += 1;
            column = 0;
        }
        if in_string {
            match c {
                _ if escaped => escaped = false,
                '\\' => escaped = true,
                '"' => in_string = false,
                _ => {}
            }
            continue;
        }
        match c {
            '"' => in_string = true,
            '{' | '[' => {
                depth += 1;
                if depth > max_depth {
                    return Some((line, column));
                }
            }
            '}' | ']' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    None
}

/// Drops resolved nodes without recursion (a tree refused for its depth can be deep).
pub(crate) fn drop_nodes(nodes: Vec<crate::Node>) {
    drop_tree(nodes, |n| n.kind.take_children());
}
