"""Free names for spawns with allow_renaming: name_2, name_3, ..., within 64 characters."""


def unique_name(name, taken, suffixes):
    """name_2, name_3, ...: the first not taken. `suffixes` remembers where each name's search
    stopped, so renaming thousands of copies of one name stays linear."""
    k = suffixes.get(name, 2)
    while candidate(name, k) in taken:
        k += 1
    suffixes[name] = k + 1
    return candidate(name, k)


def candidate(name, k):
    """name_k, the name shortened so that it stays within the 64 characters a name may have."""
    suffix = f"_{k}"
    return name[:64 - len(suffix)] + suffix

