"""The quad prediction kernel as Cortex-M4 assembly (Thumb-2, VFPv4-SP).

Used by firmware/codegen/quad_predict.py, which writes its output into
firmware/src/propid_quad_predict.h (PROPID_ARM_PREDICT_KERNEL, the quad build
on a Cortex-M4). The C kernel there, compiled with -ffp-contract=fast (the
target build's flag), is GCC's arithmetic: which product GCC fuses into an
addition (a `vfma`) and which it leaves alone (a `vmul`) decides the bits. This
module builds the same statements as the C, three-address, in the C's order,
and applies GCC's rule for contracting them (expression_graph.py, shared with
the model stage's generator).

The fused graph is then scheduled (any order of the same operations gives the
same bits): column by column, the bias columns side by side so that each row's
three elements P_c,11..13 are one VLDM; the variances' loading and noise of
the thrust and drag columns after the sweep (their registers are free then).
Registers are allocated here by a linear scan: the 18 Jacobian entries stay in
s14-s31, where the caller's code puts them (register variables); s0-s13 hold
the rest. A column's elements along its own packed row are loaded by VLDM from
a base register written back, so each block move starts where the last ended;
a value idle for long waits in a core register (VMOV), a loaded one is loaded
again. The schedule's few choices (when a value leaves its register, how many
registers a load keeps free) are the parameters of `allocate`, set to the
smallest kernel found by counting its instructions over a grid of them.

Checks: quad_predict.py evaluates the graph symbolically against the model's
F P F^T + Q (as the C kernel's); tests/host_tools/test_codegen.py compares the
graph with GCC's own contraction of the portable C, element by element; the
target test qemu.block_moves_match_portable_c compares the final states of the
builds with and without the assembly to the bit.
"""

from __future__ import annotations

from expression_graph import Graph

N_RATE, N_ROTOR, N_BIAS = 3, 4, 3
N = N_RATE + 2 * N_ROTOR + N_BIAS
FIRST_THRUST, FIRST_DRAG, FIRST_BIAS = 3, 7, 11
POOL = list(range(14))                 # s0-s13: the kernel's own registers
G_BASE = 14


def g_register(a: int, p: int) -> int:
    """The FPU register of the Jacobian entry g_a,p (s14-s31)."""
    return G_BASE + 6 * a + p

SPILL_SLOTS = 3
JOINT = (FIRST_BIAS, FIRST_BIAS + 1, FIRST_BIAS + 2)     # columns scheduled side by side


def cov_index(i: int, j: int) -> int:
    i, j = min(i, j), max(i, j)
    return i * N - i * (i - 1) // 2 + (j - i)


def build(structure):
    """The fast C kernel's statements (propid_quad_predict.h), mirrored; returns
    the graph and the ordered list of (what, ...) the asm schedule is made of."""
    graph = Graph()
    entries = len(structure[0])
    g = [[graph.leaf("G", (a, p)) for p in range(entries)] for a in range(3)]

    tables = {}

    def table(name):
        if name not in tables:
            tables[name] = graph.leaf("T", name)
        return tables[name]

    # The caller's Q dt per kind (written before the kernel: fused first).
    dt, psd = table("dt"), {k: table(f"psd_{k}") for k in ("rate", "thrust", "drag", "bias")}
    q = {k: graph.mul(psd[k], dt) for k in psd}
    stores = []           # (i, j, node, column after which it is final)
    order = []            # nodes the schedule takes first in each column
    deferred = []         # nodes the schedule takes after the sweep
    columns = []          # per column: its loads by row c, its t, its nodes
    block = {}
    block_done = {(a, b): max([b] + list(structure[b])) for a in range(3) for b in range(a, 3)}

    def kind(k):
        return "rate" if k < FIRST_THRUST else "thrust" if k < FIRST_DRAG else "drag" \
            if k < FIRST_BIAS else "bias"

    def write_block(after):
        for (a, b) in sorted(block):
            if block_done[(a, b)] == after:
                value = graph.add(block[(a, b)], q["rate"]) if a == b else block[(a, b)]
                stores.append((a, b, value, after))

    for j in range(N):
        if j > 0:
            write_block(j - 1)
        col = {c: graph.leaf("P", (c, j)) for c in range(FIRST_BIAS)}
        heads = {}
        seeds = []
        for a in (0, 1):
            products = [graph.mul(g[a][0], col[structure[a][0]]), graph.mul(g[a][1], col[structure[a][1]])]
            seeds.extend(products)
            heads[a] = graph.add(products[0], products[1])
        t = {}
        chain = {0: [], 1: [], 2: []}
        for a in (0, 1):
            acc = heads[a]
            for p in range(2, entries):
                acc = graph.add(acc, graph.mul(g[a][p], col[structure[a][p]]))
                chain[a].append(acc)
            t[a] = graph.add(acc, col[a])
        acc = col[2]
        for p in range(entries):
            acc = graph.add(acc, graph.mul(g[2][p], col[structure[2][p]]))
            chain[2].append(acc)
        t[2] = acc
        # The assembly's order (any order of the same operations gives the same
        # bits): the heads, the two thrust-entry chains side by side (each
        # loaded entry read by both, then free), the sums' last additions, the
        # yaw row's chain.
        order.append(("column", j))
        if j >= FIRST_BIAS:
            # The bias columns side by side (schedule(): one step of each in
            # turn), so each row's three elements P_c,11..13 are one VLDM: the
            # yaw row's elements first (the heads' second products), then
            # everything that reads row 0, then row 1 (the rows' own elements,
            # read again by the sums' last additions, are loaded again then),
            # the thrust and drag entries' chains, the last additions.
            order.extend(seeds + [heads[1], chain[2][0], heads[0], chain[2][1]])
        else:
            order.extend([heads[0], heads[1]] + chain[2][:2])
        for step0, step1 in zip(chain[0], chain[1]):
            order.extend([step0, step1])
        if j >= FIRST_BIAS:
            order.extend(chain[2][2:] + [t[0], t[1]])
        else:
            order.extend([t[0], t[1]])
            order.extend(chain[2][2:])
        info = {"j": j, "col": col}
        if j < FIRST_THRUST:
            rate_touched = {}
            loaded = graph.mul(table("c7"), col[j])
            for a in range(3):
                for b in range(a, 3):
                    terms = []
                    if b == j:
                        terms.append(t[a])
                        if a == b:
                            terms.append(loaded)
                    if j in structure[b]:
                        p = structure[b].index(j)
                        if a == b:
                            terms.append(graph.mul(graph.add(t[a], graph.mul(g[b][p], loaded)), g[b][p]))
                        else:
                            terms.append(graph.mul(t[a], g[b][p]))
                    if not terms:
                        continue
                    if j == 0:
                        value = terms[0]
                        for term in terms[1:]:
                            value = graph.add(value, term)
                        block[(a, b)] = value
                    else:
                        for term in terms:
                            block[(a, b)] = graph.add(block[(a, b)], term)
                    rate_touched[(a, b)] = block[(a, b)]
            for a in range(3):
                for b in list(range(a + 1, 3)) + [a]:
                    if (a, b) in rate_touched:
                        order.append(rate_touched[(a, b)])
            columns.append(info)
            continue
        loaded = None
        if any(j in structure[a] for a in range(3)):
            loaded = graph.mul(table("c7"), col[j])
        touched = {}
        for a in range(3):
            for b in range(a, 3):
                if j in structure[b]:
                    p = structure[b].index(j)
                    if a == b:
                        term = graph.mul(graph.add(t[a], graph.mul(g[b][p], loaded)), g[b][p])
                    else:
                        term = graph.mul(t[a], g[b][p])
                    block[(a, b)] = graph.add(block[(a, b)], term)
                    touched[(a, b)] = block[(a, b)]
        for a in range(3):
            stores.append((a, j, t[a], j))
        # Each t_a's products into the later rows' block sums first, then its own
        # row's (t_a + g c P_jj) g, which can overwrite t_a in its register.
        for a in range(3):
            for b in list(range(a + 1, 3)) + [a]:
                if (a, b) in touched:
                    order.append(touched[(a, b)])
        own = col[j] if j < FIRST_BIAS else graph.leaf("P", (j, j))
        factor = table("drag_factor") if kind(j) == "drag" else table("c1l")
        scaled = graph.mul(factor, own)
        diag = graph.add(scaled, q[kind(j)])
        if j < FIRST_BIAS:
            deferred.extend([scaled, diag])     # after the sweep: its registers are free then
        stores.append((j, j, diag, j))
        columns.append(info)
    write_block(N - 1)
    graph.contract([s[2] for s in stores])
    return graph, g, stores, columns, order, deferred


def evaluate(graph, symbols):
    """Each node's value, symbolically (sympy), fma(x, y, z) = x y + z."""
    value = {}
    for node in graph.nodes:
        if node.kind in ("P", "G", "T"):
            value[node] = symbols(node)
        elif node.kind == "mul":
            value[node] = value[node.args[0]] * value[node.args[1]]
        elif node.kind == "add":
            value[node] = value[node.args[0]] + value[node.args[1]]
        elif node.kind == "fma":
            value[node] = value[node.args[0]] * value[node.args[1]] + value[node.args[2]]
    return value


def schedule(graph, stores, order, deferred=()):
    """The kernel's operations in order: in each column the nodes `order` puts
    first, then the column's others as the C writes them; each store right
    after its value. Loads are added by the allocator where first needed."""
    store_of = {}
    for i, j, node, _after in stores:
        store_of.setdefault(node, []).append((i, j))
    preferred = {}
    current = None
    for item in order:
        if isinstance(item, tuple):
            current = item[1]
            preferred[current] = []
        else:
            preferred[current].append(item)
    ops = []
    done = set()
    later = set(deferred)
    row_stores = {}

    def put(node, now=False):
        if node in done or node.kind not in ("mul", "add", "fma") or (node in later and not now):
            return
        for arg in node.args:
            put(arg)
        done.add(node)
        ops.append(("op", node))
        for i, j in store_of.get(node, []):
            if i < N_RATE and j in JOINT:
                # Row i's elements of the side-by-side columns: stored together
                # once the last is computed (one VSTM when their registers run on).
                pending = row_stores.setdefault(i, [])
                pending.append((node, (i, j)))
                if len(pending) == len(JOINT):
                    pending.sort(key=lambda item: item[1][1])
                    ops.append(("stores", [item[0] for item in pending], [item[1] for item in pending]))
            else:
                ops.append(("store", node, (i, j)))

    first_of = {id(nodes[0]): j for j, nodes in preferred.items() if nodes}
    for node in graph.nodes:
        # A column's preferred nodes go first when its first node is reached;
        # the bias columns' together, one step of each in turn.
        column = first_of.get(id(node))
        if column is not None:
            # (the last column first: the allocator gives its values the
            # highest free registers, so each row's three run upwards, for VSTM)
            together = [k for k in reversed(JOINT) if column in JOINT] or [column]
            for steps in zip(*(preferred[k] for k in together)):
                for step in steps:
                    put(step)
        put(node)
    for node in deferred:
        put(node, now=True)
    return ops


class AllocationError(Exception):
    pass


def load_groups(columns, split_rates=True):
    """The row-consecutive elements each column loads with one VLDM: P(j, c)
    for c = j.., split where the thrust and drag entries part (c = 7)."""
    group_of = {}
    by_column = {info["j"]: info for info in columns}
    for c in range(FIRST_BIAS):
        members = [by_column[k]["col"][c] for k in JOINT]
        for member in members:
            group_of[member] = members
    for info in columns:
        j = info["j"]
        if j >= FIRST_BIAS:
            continue
        if split_rates:
            parts = [list(range(j, FIRST_THRUST)), list(range(max(j, FIRST_THRUST), FIRST_DRAG)),
                     list(range(max(j, FIRST_DRAG), FIRST_BIAS))]
        else:
            parts = [list(range(j, FIRST_DRAG)), list(range(max(j, FIRST_DRAG), FIRST_BIAS))]
        for part in parts:
            members = [info["col"][c] for c in part if c >= j]
            if len(members) >= 2:
                for member in members:
                    group_of[member] = members
    return group_of


def allocate(graph, g, ops, group_of, table_names, reload_distance=40, spill_distance=150, reserve=0):
    """Registers for every value (linear scan over the straight-line ops).
    Returns the assembly lines and counts by kind."""
    pinned = {g[a][p]: g_register(a, p) for a in range(3) for p in range(len(g[0]))}
    # Every position where a node is read.
    reads = {}
    def operands_of(entry):
        return entry[1].args if entry[0] == "op" else entry[1] if entry[0] == "stores" else [entry[1]]

    for index, entry in enumerate(ops):
        for node in operands_of(entry):
            reads.setdefault(node, []).append(index)
    reg = {}
    owner = {}
    lines = []
    counts = {}
    base_at = [None]        # address the base register points at (after a VLDM write-back)
    loaded_upto = {}
    last_block = [None, None]   # the last block move's line and start address
    spilled = {}            # values kept in core registers meanwhile (VMOV both ways)
    reloaded = set()
    slots_used = set()
    stored = set()

    def point_base(address):
        """The base register at `address` for a VLDM/VSTM: as it is after the
        last one's write-back, or that one's start again (its write-back
        dropped), or by an ADD."""
        if base_at[0] == address:
            return
        if last_block[0] is not None and last_block[1] == address:
            lines[last_block[0]] = lines[last_block[0]].replace("%[base]!", "%[base]", 1)
            base_at[0] = address
            return
        emit("add", f"add %[base], %[cov], #{address}")
        base_at[0] = address

    def block_move(mnemonic, first, count, start):
        """One VLDM/VSTM of `count` registers from s`first` at the base (which
        points at byte offset `start`), written back."""
        registers = f"s{first}" if count == 1 else f"s{first}-s{first + count - 1}"
        kind = "vldm" if mnemonic == "vldmia" else "vstm"
        emit(kind, f"{mnemonic} %[base]!, {{{registers}}}")
        last_block[0], last_block[1] = len(lines) - 1, start
        base_at[0] = start + 4 * count

    def emit(kind, text):
        counts[kind] = counts.get(kind, 0) + 1
        lines.append(text)

    def free_regs():
        return [r for r in POOL if r not in owner]

    def take(node, r):
        reg[node] = r
        owner[r] = node

    def release(node):
        r = reg.pop(node)
        del owner[r]

    def new_reg(index):
        free = free_regs()
        if not free:
            raise AllocationError(f"no free register at op {index}: live "
                                  + ", ".join(describe(n) for n in owner.values()))
        return free[-1]

    def next_read(node, index):
        for position in reads.get(node, []):
            if position > index:
                return position
        return None

    def load(node, index):
        if node.kind == "T":
            r = new_reg(index)
            take(node, r)
            where_from = table_names[node.key]
            if where_from[0] == "core":         # a value passed in a core register
                emit("vmov", f"vmov s{r}, %[{where_from[1]}]")
            else:
                emit("vldr", f"vldr s{r}, [%[{where_from[0]}], #{where_from[1]}]")
            return
        if node in spilled:
            r = new_reg(index)
            take(node, r)
            emit("vmov", f"vmov s{r}, %[spill{spilled.pop(node)}]")
            return
        members = group_of.get(node)
        if members is not None and loaded_upto.get(id(members), 0) > members.index(node):
            # Loaded before: again as a group when every member is out of the
            # registers and read again (the bias rows' own elements), else alone.
            again = [m for m in members if m not in reg and next_read(m, index - 1) is not None]
            if len(again) == len(members) and len(members) > 1 and id(members) not in reloaded:
                reloaded.add(id(members))
                free = free_regs()
                run = next((f for f in free if all(f + k in free for k in range(len(members)))), None)
                if run is not None:
                    address = 4 * cov_index(*members[0].key)
                    point_base(address)
                    block_move("vldmia", run, len(members), address)
                    for k, member in enumerate(members):
                        take(member, run + k)
                    return
            members = None
        if members is None:
            if node.key in stored:
                raise AllocationError(f"P{node.key} read again after its store")
            r = new_reg(index)
            take(node, r)
            emit("vldr", f"vldr s{r}, [%[cov], #{4 * cov_index(*node.key)}]")
            return
        # From the group's next element through the one needed, and on while
        # registers are free (keeping `reserve`), in the longest runs of
        # consecutive free registers: as many VLDMs as it takes, each written
        # back, so each starts where the last ended.
        start = loaded_upto.get(id(members), 0)
        need = members.index(node) + 1
        address = 4 * cov_index(*members[start].key)
        point_base(address)
        position = start
        while position < need or (position < len(members) and len(free_regs()) > reserve):
            free = set(free_regs())
            limit = (need if len(free) - (need - position) <= reserve else len(members)) - position
            limit = max(1, min(limit, len(free) - reserve if position >= need else limit))
            best, best_len = None, 0
            for first in POOL:
                length = 0
                while first + length in free and length < limit:
                    length += 1
                if length > best_len:
                    best, best_len = first, length
            if best is None:
                raise AllocationError(f"no free register for a VLDM at op {index}: live "
                                      + ", ".join(describe(n) for n in owner.values()))
            block_move("vldmia", best, best_len, base_at[0])
            for k in range(best_len):
                take(members[position + k], best + k)
            position += best_len
        loaded_upto[id(members)] = position

    def where(node):
        return f"s{pinned[node]}" if node in pinned else f"s{reg[node]}"

    def describe(node):
        return f"{node.kind}{node.key if node.key is not None else id(node) % 1000}"

    for index, entry in enumerate(ops):
        node = entry[1]
        operands = operands_of(entry)
        for operand in operands:
            if operand not in pinned and operand not in reg:
                if operand.kind in ("P", "T") or operand in spilled:
                    load(operand, index)
                else:
                    raise AllocationError(f"value not in a register at op {index}")
        if entry[0] == "store":
            emit("vstr", f"vstr {where(node)}, [%[cov], #{4 * cov_index(*entry[2])}]")
        elif entry[0] == "stores":
            registers = [reg[value] for value in node]
            if registers == list(range(registers[0], registers[0] + len(registers))):
                address = 4 * cov_index(*entry[2][0])
                point_base(address)
                block_move("vstmia", registers[0], len(registers), address)
            else:
                for value, key in zip(node, entry[2]):
                    emit("vstr", f"vstr {where(value)}, [%[cov], #{4 * cov_index(*key)}]")
            for key in entry[2]:
                stored.add(key)
            for value in node:
                if value in reg and next_read(value, index) is None:
                    release(value)
        else:
            dying = [a for a in operands if a not in pinned and next_read(a, index) is None]
            if node.kind == "fma":
                x, y, acc = node.args
                text_x, text_y, text_acc = where(x), where(y), where(acc)
                if acc in dying:
                    r = reg[acc]
                    release(acc)
                else:
                    r = new_reg(index)
                    emit("vmov", f"vmov.f32 s{r}, {text_acc}")
                for a in dying:
                    if a is not acc and a in reg:
                        release(a)
                emit("vfma", f"vfma.f32 s{r}, {text_x}, {text_y}")
                take(node, r)
            else:
                x, y = node.args
                text_x, text_y = where(x), where(y)
                for a in dying:
                    if a in reg:
                        release(a)
                r = new_reg(index)
                mnemonic = "vmul" if node.kind == "mul" else "vadd"
                emit(mnemonic, f"{mnemonic}.f32 s{r}, {text_x}, {text_y}")
                take(node, r)
        if entry[0] == "store":
            stored.add(entry[2])
        if entry[0] == "store" and node in reg and next_read(node, index) is None:
            release(node)
        # Values read again only much later leave their registers: loaded
        # values are loaded again then, computed ones stored in the spill area.
        for value in list(owner.values()):
            following = next_read(value, index)
            if following is None:
                continue
            if following - index > (reload_distance if value.kind in ("P", "T") else spill_distance):
                if value.kind not in ("P", "T"):
                    free_slots = set(range(SPILL_SLOTS)) - set(spilled.values())
                    if not free_slots:
                        raise AllocationError(f"no free spill register at op {index}")
                    slot = min(free_slots)
                    slots_used.add(slot)
                    emit("vmov", f"vmov %[spill{slot}], s{reg[value]}")
                    spilled[value] = slot
                release(value)
    counts["spill registers"] = len(slots_used)
    return lines, counts


TABLES = {"c7": ("k", 0), "c1l": ("k", 4), "dt": ("core", "dt"), "drag_factor": ("core", "drag_factor"),
          "psd_rate": ("psd", 0), "psd_thrust": ("psd", 4), "psd_drag": ("psd", 8), "psd_bias": ("psd", 12)}


def kernel(structure, **tuning):
    """The assembly kernel's lines and its operation counts."""
    graph, g, stores, columns, order, deferred = build(structure)
    ops = schedule(graph, stores, order, deferred)
    lines, counts = allocate(graph, g, ops, load_groups(columns), TABLES, **tuning)
    return graph, stores, lines, counts


def c_function(structure, lines, counts) -> str:
    """The C function around the assembly (GNU inline assembly, one statement)."""
    entries = len(structure[0])
    pins = []
    inputs = []
    for a in range(3):
        for p in range(entries):
            pins.append(f"    register float g{a}_{p} __asm__(\"s{g_register(a, p)}\") = jacobian_dt[{a}][{p}];")
            inputs.append(f"\"t\"(g{a}_{p})")
    body = "\n".join(f"        \"{line}\\n\\t\"" for line in lines)
    spills = counts.get("spill registers", 0)
    instructions = sum(v for k, v in counts.items() if k != "spill registers")
    summary = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()) if k != "spill registers")
    clobbers = ", ".join(f"\"s{r}\"" for r in POOL)
    input_lines = []
    for start in range(0, len(inputs), 6):
        input_lines.append("          " + ", ".join(inputs[start:start + 6]))
    spill_decl = "".join(f", spill{k}" for k in range(spills))
    spill_outputs = "".join(f", [spill{k}] \"=&r\"(spill{k})" for k in range(spills))
    return f"""/* The Cortex-M4 kernel (PROPID_ARM_PREDICT_KERNEL): the fast kernel's operations
 * above, the same fused multiply-adds (GCC's contraction of that C, reproduced by
 * the generator), so the same bits, scheduled and register-allocated by the
 * generator: the 18 Jacobian entries in s14-s31 (where the caller's code puts
 * them), each column's elements along its packed row by VLDM, the variances of
 * the coefficients' loading and noise after the sweep; dt and the drag factor
 * arrive in core registers, {spills} value(s) wait in core registers while idle.
 * {instructions} instructions ({summary}). */
static const float propid_quad_predict_constants[2] = {{{entries + 1}.0f * PROPID_RATE_LOADING,
                                                        1.0f + PROPID_VAR_LOADING}};

static inline __attribute__((always_inline)) void
propid_quad_predict_covariance_arm(float *restrict cov, const float jacobian_dt[3][PROPID_JAC_ROW],
                                   const float kind_process_psd[4], float dt, float drag_factor)
{{
    _Static_assert(PROPID_MAX_STATES == {N}, "the offsets below are those of the {N}-state packed triangle");
    _Static_assert(PROPID_KIND_RATE == 0u && PROPID_KIND_THRUST == 1u && PROPID_KIND_DRAG == 2u &&
                   PROPID_KIND_BIAS == 3u, "the offsets below read kind_process_psd in this order");
{chr(10).join(pins)}
    uint32_t base{spill_decl};
    __asm__ volatile(
{body}
        : [base] "=&r"(base){spill_outputs}
        : [cov] "r"(cov), [psd] "r"(kind_process_psd), [k] "r"(propid_quad_predict_constants),
          [dt] "r"(propid_float_bits(dt)), [drag_factor] "r"(propid_float_bits(drag_factor)),
{(","+chr(10)).join(input_lines)}
        : {clobbers}, "memory");
}}
"""
