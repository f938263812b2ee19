"""Physical constants and unit factors shared by every layer, each with its source.

Bottom of the layer order (see ``.importlinter``): imports nothing from the package.
"""

from __future__ import annotations

#: Standard acceleration of gravity [m/s²]: the conventional value adopted by the 3rd CGPM
#: (1901), ISO 80000-3:2019 item 3-9.2, NIST SP 330 (2019). Used for every weight (vehicle
#: loads, moving forces) and every limit given in g (the thesis criterion 0.005 g).
STANDARD_GRAVITY = 9.80665

#: Bytes of one IEEE 754 double-precision number (dense blocks, HDF5 ``f8`` datasets).
BYTES_PER_DOUBLE = 8

#: Bytes per GB (decimal gigabyte, as MUMPS reports its INFOG(17)/INFOG(27) in MB = 1e6 B).
BYTES_PER_GB = 1e9

#: Metres per inch (exact, international yard and pound agreement, 1959).
METRES_PER_INCH = 0.0254

#: Preferred (nominal) mantissas of the base-10 one-third-octave band centres: ISO 266:1997
#: (the R10 preferred numbers), as IEC 61260-1:2014 labels the bands.
THIRD_OCTAVE_MANTISSAS = (1.0, 1.25, 1.6, 2.0, 2.5, 3.15, 4.0, 5.0, 6.3, 8.0)
