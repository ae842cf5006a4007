"""Atomic counters for the threads of one parallel region (the contact solve's workers): Numba
has no atomics of its own, so these emit LLVM's atomic instructions on an int64 array element.

A worker publishes its progress with atomic_store (release: its writes before it are visible to
whoever sees the new value), claims work with atomic_add, and waits for others' progress with
atomic_load (acquire: what it reads after it is what they wrote before their store).
"""
import platform

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

# x86's PAUSE tells the core it is spinning: the waiting loop yields its pipeline to the other
# hyper-thread and leaves the loop without a memory-order flush. Other machines spin plainly.
_PAUSE = "llvm.x86.sse2.pause" if platform.machine().lower() in ("x86_64", "amd64", "i686") else None


def _element_pointer(context, builder, array_type, array, index):
    ary = context.make_array(array_type)(context, builder, array)
    return cgutils.get_item_pointer(context, builder, array_type, ary, [index])


@intrinsic
def atomic_add(typingctx, array, index, value):
    """array[index] += value as one atomic step; returns the value before."""
    if not (isinstance(array, types.Array) and array.dtype == types.int64):
        return None
    sig = types.int64(array, types.intp, types.int64)

    def codegen(context, builder, signature, args):
        array_value, index_value, added = args
        pointer = _element_pointer(context, builder, signature.args[0], array_value, index_value)
        return builder.atomic_rmw("add", pointer, added, "seq_cst")
    return sig, codegen


@intrinsic
def atomic_load(typingctx, array, index):
    """array[index], read atomically (acquire)."""
    if not (isinstance(array, types.Array) and array.dtype == types.int64):
        return None
    sig = types.int64(array, types.intp)

    def codegen(context, builder, signature, args):
        array_value, index_value = args
        pointer = _element_pointer(context, builder, signature.args[0], array_value, index_value)
        return builder.load_atomic(pointer, "acquire", 8)
    return sig, codegen


@intrinsic
def atomic_store(typingctx, array, index, value):
    """array[index] = value, written atomically (release: what this thread wrote before it is
    visible to whoever reads the new value)."""
    if not (isinstance(array, types.Array) and array.dtype == types.int64):
        return None
    sig = types.void(array, types.intp, types.int64)

    def codegen(context, builder, signature, args):
        array_value, index_value, stored = args
        pointer = _element_pointer(context, builder, signature.args[0], array_value, index_value)
        builder.store_atomic(stored, pointer, "release", 8)
        return context.get_dummy_value()
    return sig, codegen


@intrinsic
def spin_pause(typingctx):
    """One pause of a spin-wait loop."""
    sig = types.void()

    def codegen(context, builder, signature, args):
        if _PAUSE is not None:
            pause = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), []), _PAUSE)
            builder.call(pause, [])
        return context.get_dummy_value()
    return sig, codegen


@intrinsic
def yield_thread(typingctx):
    """sched_yield(2): lets the OS run another thread on this core. A waiter that has spun for
    long is waiting on a thread the OS took off its core (a machine busier than its cores), which
    needs the core back more than the waiter does."""
    sig = types.int32()

    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(32), []), "sched_yield")
        return builder.call(fn, [])
    return sig, codegen
