"""Building and running the gainlink firmware: CMake driver, size report, QEMU runner, PIL, the image on its UART."""
