from fusiontrack.cli import main

main()
