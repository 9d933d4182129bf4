from optipose.cli.app import main

main()
