"""Private helpers shared by every subpackage (validation, atomic writes, JIT defaults)."""
