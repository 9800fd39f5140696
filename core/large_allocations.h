#pragma once
// How the process allocates its large buffers (images, stacks, bands).
//
// glibc gives every allocation above its mmap threshold (at most 32 MB, adjusted at run time) its
// own mapping and unmaps it on free. A 9 MP band of a fine stack is about 100 MB a frame, so each
// frame read, rectified and freed made the kernel map, zero and fault in fresh pages again: on
// the 2-core VM the rectification of the 9 MP plain spent most of its time in page faults.
// KeepLargeAllocationsInTheHeap raises the mmap threshold (to 1 GiB) and the trim threshold (the
// free memory at the heap's top kept for reuse, also 1 GiB), so a freed buffer is reused by the
// next one of its size. The peak resident memory is unchanged (measured: docs/process.md,
// "Large allocations"); memory freed below that peak stays with the process until it exits.

namespace u3mscan {

// Applies the setting to this process (glibc; a no-op elsewhere). Returns true when it took effect.
// Call once, early (the CLI's main does); later allocations follow it.
bool KeepLargeAllocationsInTheHeap();

}  // namespace u3mscan
