"""The generated kernel modules, ``eelsim.batch.kernels.<name>``: files in the kernel cache folder.

Nothing in this package is written by hand. ``eelsim.batch.loading.load_kernel_source`` writes
each module's text to ``eelsim.batch.loading.kernel_cache_dir()`` and imports it from there as a
module of this package, whose search path is that folder: so a kernel module is found by its
name in every process, as numba's on-disk cache needs when it loads compiled code.
"""

from eelsim.batch.loading import kernel_cache_dir

__path__ = [str(kernel_cache_dir())]
