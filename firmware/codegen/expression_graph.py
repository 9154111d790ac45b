"""Three-address statements in the C's order, and GCC's rule for fusing their products.

Both assembly generators (quad_predict_arm.py, quad_model_arm.py) mirror a C function
statement by statement. Compiled with -ffp-contract=fast (the target build's flag), GCC
fuses a product into the additions that use it (`vfma`) and into the subtractions that
subtract it (`vfms`) only when every use of the product is such an addition or
subtraction; it takes the products in the order they are written. Which products are
fused decides the bits, so the generators apply the same rule here before scheduling.
"""

from __future__ import annotations

OPERATIONS = ("mul", "add", "sub", "fma", "fms", "dead")


class Node:
    __slots__ = ("kind", "args", "key", "uses", "name", "order")

    def __init__(self, kind, args=(), key=None):
        self.kind = kind          # a leaf's kind (the generator's own letters) or one of OPERATIONS:
        #                           'fma' is x y + z, 'fms' is z - x y
        self.args = list(args)
        self.key = key
        self.uses = []
        self.name = None
        self.order = 0

    def is_leaf(self):
        return self.kind not in OPERATIONS


class Graph:
    """The statements as nodes. With `shared_leaves`, one leaf per (kind, key, tag): a
    memory location or constant read again is the same node; without it every read is
    its own leaf (the generator decides when a value is loaded)."""

    def __init__(self, shared_leaves: bool = False):
        self.nodes: list[Node] = []
        self.leaves: dict = {}
        self.shared_leaves = shared_leaves

    def leaf(self, kind, key=None, tag=0):
        if not self.shared_leaves:
            node = Node(kind, (), key)
            self.nodes.append(node)
            return node
        if (kind, key, tag) not in self.leaves:
            node = Node(kind, (), key)
            self.nodes.append(node)
            self.leaves[(kind, key, tag)] = node
        return self.leaves[(kind, key, tag)]

    def op(self, kind, *args):
        node = Node(kind, args)
        self.nodes.append(node)
        return node

    def mul(self, x, y):
        return self.op("mul", x, y)

    def add(self, x, y):
        return self.op("add", x, y)

    def sub(self, x, y):
        return self.op("sub", x, y)

    def contract(self, roots):
        """GCC's contraction: `roots` are the outputs (a use that is no addition)."""
        for index, node in enumerate(self.nodes):
            node.order = index
            node.uses = []
        for node in self.nodes:
            for arg in node.args:
                arg.uses.append(node)
        for root in roots:
            root.uses.append(None)
        for node in self.nodes:
            if node.kind != "mul" or not node.uses:
                continue
            if not all(use is not None and (use.kind == "add" or (use.kind == "sub" and use.args[1] is node))
                       for use in node.uses):
                continue
            for use in node.uses:
                if use.kind == "add":
                    other = use.args[1] if use.args[0] is node else use.args[0]
                    use.kind = "fma"
                else:
                    other = use.args[0]
                    use.kind = "fms"
                use.args = [node.args[0], node.args[1], other]
            node.kind = "dead"
