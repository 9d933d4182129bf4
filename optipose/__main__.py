from optipose.cli import main

main()
