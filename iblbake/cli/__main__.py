"""`python -m iblbake.cli`: the same as the `iblbake` console script."""
from iblbake.entry import main

main()
