"""Imported last by every forkserver of facegen's process pools (processes.ProcessPool): when the server's
work is over (its pool is closed, or its owner and then its workers ended), it exits at once, by the first
of its exit handlers, instead of through the teardown of what it preloaded (torch, USD: a second, several on
a busy machine). A forkserver holds nothing that needs saving: ProcessPool.close SIGKILLs it.
"""

import atexit
import os

atexit.register(os._exit, 0)  # handlers run last-registered first: this one before torch's and USD's
