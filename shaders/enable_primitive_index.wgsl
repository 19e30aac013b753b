// Must come first in a module: turns on @builtin(primitive_index).
enable primitive_index;
