"""The import-cycle search the layer tests share (core's, mc_ao's and the bench's import graphs)."""


def cycle(graph):
    """The first import cycle of ``graph`` ({module: the modules it imports}) in a depth-first walk of
    the modules in sorted order: the list of modules from one back to itself, or None without a cycle."""
    state, stack = {}, []

    def visit(module):
        state[module] = "open"
        stack.append(module)
        for other in sorted(graph.get(module, ())):
            if state.get(other) == "open":
                return stack[stack.index(other):] + [other]
            if other not in state:
                found = visit(other)
                if found:
                    return found
        stack.pop()
        state[module] = "done"
        return None

    for module in sorted(graph):
        if module not in state:
            found = visit(module)
            if found:
                return found
    return None


def assert_no_cycle(graph):
    """Fail with the cycle's modules, 'import cycle: a -> b -> a', where ``graph`` has one."""
    found = cycle(graph)
    assert found is None, "import cycle: " + " -> ".join(found)
